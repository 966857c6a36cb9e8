"""The record-design note: a gap that lies after the last training window only."""

import numpy as np

from fmvmg_sim.diagnosis.forward import IRATE
from fmvmg_sim.diagnosis.windows import after_training_note, window_masks, window_stats
from tests.test_diagnosis_localize import _oven_prep


def _setup():
    prep = _oven_prep()
    train = prep.folds()[-1]["train"]
    return prep, train, window_masks(prep, train)


def _white(prep, rng, after_scale=1.0, train_scale=1.0, masks=None):
    Z = np.full((prep.n_blocks, 5), np.nan)
    z = rng.standard_normal(prep.n_blocks)
    if masks is not None:
        z = np.where(masks["after"], after_scale * z, z)
        z = np.where(masks["train"], train_scale * z, z)
    Z[:, IRATE] = z
    return Z


def test_windows_split_the_record_at_the_last_training_block():
    # the last fold trains on the record up to 76 % of its length (its test segment starts at 80 %, after a gap
    # of a fifth of a segment): the blocks after that window are the last 24 %
    prep, train, m = _setup()
    assert not (m["train"] & m["after"]).any()
    assert abs(m["after"].mean() - 0.24) < 0.01
    assert abs(m["train"].mean() - 0.76) < 0.01
    tb = prep.block_time_s()
    assert tb[m["after"]].min() > tb[m["train"]].max()


def test_a_gap_after_the_training_window_only_fires_the_note():
    prep, train, m = _setup()
    rng = np.random.default_rng(3)
    nulls = [window_stats(prep, _white(prep, rng), m) for _ in range(4)]
    end_s = float(prep.block_time_s()[train].max())
    # twice the null's variance after the window, none on it: the note names the channel and the time
    late = after_training_note(window_stats(prep, _white(prep, rng, 2.0, masks=m), m), nulls, end_s)
    assert late["fires"] and late["channels"] == ["rate_V"]
    assert late["tests"]["rate_V@after"]["z"] > 5 and not late["tests"]["rate_V@train"]["significant"]
    assert f"{end_s / 3600:.2f} h" in late["advice"]
    # the same excess on the training window as well: a gap the training window holds, no note
    both = after_training_note(window_stats(prep, _white(prep, rng, 2.0, 2.0, masks=m), m), nulls, end_s)
    assert both["tests"]["rate_V@after"]["significant"] and not both["fires"]
    assert "advice" not in both


def test_the_note_rarely_fires_without_a_gap():
    # white residuals like the null's: Holm at 5 % over both windows keeps the note's false-alarm rate near it
    prep, train, m = _setup()
    rng = np.random.default_rng(5)
    end_s = float(prep.block_time_s()[train].max())
    fired = 0
    for _ in range(100):
        nulls = [window_stats(prep, _white(prep, rng), m) for _ in range(4)]
        fired += after_training_note(window_stats(prep, _white(prep, rng), m), nulls, end_s)["fires"]
    assert fired <= 10, fired
