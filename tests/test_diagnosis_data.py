"""Block data of a record: the applied rate at the interval centres, transient blocks, noise mask."""

import numpy as np

from fmvmg_sim.diagnosis.data import prepare
from fmvmg_sim.diagnosis.fitting import transient_blocks
from fmvmg_sim.record import Record


def _record(n=3700, step_at=200.5, step_dps=50.0):
    t = np.arange(1.0, n + 1.0)                     # outputs are means over (t - 1, t]
    rate_true = np.where(t >= step_at, step_dps, 0.0)  # the table read at the sample times
    # the output holds the interval mean of the applied rate
    mean = np.clip(t - step_at, 0.0, 1.0) * step_dps
    cols = {"time_s": t, "temperature_C": np.full(n, 25.0), "rate_dps": mean, "rate_true_dps": rate_true}
    return Record(cols, {})


def test_applied_rate_is_taken_at_interval_centres():
    prep = prepare(_record(), 0.01)
    # the interval (200, 201] holds half a second of 50 deg/s: its centre value is 25, not the 50 read at t=201
    i = 200
    assert prep.rate_true_dps[i] == 25.0
    np.testing.assert_allclose(prep.block_mean(prep.rate_true_dps), prep.block_mean(np.asarray(prep.obs["rate_V"]) / 0.01))


def test_transient_blocks_and_static_mask():
    prep = prepare(_record(), 0.01)
    tb = transient_blocks(prep)
    # 10 s blocks; the centre-interpolated rate changes across samples 199-201 (blocks 19 and 20):
    # those blocks and the one after are transient
    assert set(np.flatnonzero(tb)) == {19, 20, 21}
    quiet = prep.static_rate_samples(margin_s=30.0)
    assert quiet[:170].all() and not quiet[171:].any()  # the step lasts to the end
