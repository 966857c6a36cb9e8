"""Block data of a record: the applied rate at the interval centres, transient blocks, noise mask."""

import numpy as np

from fmvmg_sim.diagnosis.data import prepare
from fmvmg_sim.diagnosis.fitting import transient_blocks
from fmvmg_sim.diagnosis.forward import CHANNELS
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


def _quantised_record(noise_V, lsb_V=0.01, n=7200, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(1.0, n + 1.0)
    slow_V = 0.05 * np.sin(2 * np.pi * t / 5000.0)     # a slow drift over a few lsb
    rate_V = np.round((slow_V + noise_V * rng.standard_normal(n)) / lsb_V) * lsb_V
    cols = {"time_s": t, "temperature_C": np.full(n, 25.0), "rate_dps": rate_V / 0.01, "rate_V": rate_V,
            "rate_true_dps": np.zeros(n)}
    return Record(cols, {}), slow_V


def test_coarse_recorder_sets_a_floor_on_block_means():
    # noise far below the lsb: the block means follow a staircase of the drift, an error of
    # L / sqrt(12) rms that no averaging removes; the floor is that, and the staircase residual
    # of the smooth truth stays near unit variance against the block sigma
    rec, slow_V = _quantised_record(noise_V=1e-4)
    prep = prepare(rec, 0.01)
    i = CHANNELS.index("rate_V")
    assert abs(prep.lattice()[i] - 0.01) < 1e-9
    assert abs(prep.quantization_floor()[i] - 0.01 / np.sqrt(12)) < 1e-4
    z = (prep.block_obs()[:, i] - prep.block_mean(slow_V)) / prep.block_sigma()[:, i]
    assert 0.3 < np.nanmean(z ** 2) < 1.5
    # noise above the lsb dithers the quantiser: no floor beyond the noise itself
    rec, _ = _quantised_record(noise_V=0.02)
    prep = prepare(rec, 0.01)
    assert prep.quantization_floor()[i] < 1e-6


def test_rate_stuck_on_one_level_takes_the_quadrature_step():
    """A converter step far above the rate signal: the rate never leaves 0, the quadrature shows the step."""
    from fmvmg_sim.diagnosis.noise_effects import quantization_candidate

    rng = np.random.default_rng(3)
    n, lsb = 7200, 0.02
    t = np.arange(1.0, n + 1.0)
    quad_V = np.round((1.7 + 0.08 * np.sin(2 * np.pi * t / 6000.0) + 1e-4 * rng.standard_normal(n)) / lsb) * lsb
    rate_V = np.round(1e-3 * rng.standard_normal(n) / lsb) * lsb               # every sample rounds to 0
    cols = {"time_s": t, "temperature_C": np.full(n, 25.0), "rate_dps": rate_V / 0.01, "rate_V": rate_V,
            "quadrature_V": quad_V, "rate_true_dps": np.zeros(n)}
    prep = prepare(Record(cols, {}), 0.01)
    L = prep.lattice()
    assert abs(L[CHANNELS.index("quadrature_V")] - lsb) < 1e-9
    assert L[CHANNELS.index("rate_V")] == L[CHANNELS.index("quadrature_V")]
    assert abs(prep.quantization_floor()[CHANNELS.index("rate_V")] - lsb / np.sqrt(12)) < 1e-4
    q = quantization_candidate(prep, nominal_lsb_V=1e-4)
    assert q is not None and abs(q["lsb_V"] - lsb) < 1e-9 and q["on_lattice"] == 1.0
    # a rate output that moves but has no lattice keeps none, whatever the quadrature shows
    cols["rate_V"] = 1e-3 * rng.standard_normal(n)
    cols["rate_dps"] = cols["rate_V"] / 0.01
    assert prepare(Record(cols, {}), 0.01).lattice()[CHANNELS.index("rate_V")] == 0.0


def test_a_lattice_shifted_by_an_offset_after_the_converter_is_found_and_read_off():
    """An offset the data acquisition adds after the converter (here 17.8 mV on a 6 mV step: 0.97 of a step off the
    zero-through lattice) leaves the samples on a shifted lattice: its step and phase are read, every sample is on it,
    and the quantisation candidate is named with the record's step."""
    from fmvmg_sim.diagnosis.data import lattice_offset, on_lattice
    from fmvmg_sim.diagnosis.noise_effects import quantization_candidate

    rng = np.random.default_rng(5)
    n, lsb, off = 7200, 0.0060027, 0.0178
    t = np.arange(1.0, n + 1.0)
    slow = 0.03 * np.sin(2 * np.pi * t / 5000.0)
    rate_V = np.round((slow + 1e-3 * rng.standard_normal(n)) / lsb) * lsb + off
    cols = {"time_s": t, "temperature_C": np.full(n, 25.0), "rate_dps": rate_V / 0.01, "rate_V": rate_V,
            "rate_true_dps": np.zeros(n)}
    prep = prepare(Record(cols, {}), 0.01)
    i = CHANNELS.index("rate_V")
    assert on_lattice(rate_V, lsb, offset_V=0.0) < 0.05               # read through zero, the lattice is missed
    assert abs(lattice_offset(rate_V, lsb) - np.mod(off, lsb)) < 1e-9
    assert abs(prep.lattice()[i] - lsb) < 1e-9 and abs(prep.lattice_offsets()[i] - np.mod(off, lsb)) < 1e-9
    q = quantization_candidate(prep, nominal_lsb_V=1e-4)
    assert q is not None and abs(q["lsb_V"] - lsb) < 1e-9 and q["on_lattice"] == 1.0


def _temperature_record(temp_C, n=7200):
    t = np.arange(1.0, n + 1.0)
    cols = {"time_s": t, "temperature_C": temp_C(t), "rate_dps": np.zeros(n), "rate_true_dps": np.zeros(n)}
    return Record(cols, {})


def test_temperature_coverage_finds_held_out_data_beyond_the_training_range():
    from fmvmg_sim.diagnosis.data import BLOCK_S, GAP_FRACTION, N_SEGMENTS
    n, r = 7200, 60.0 / 7200.0                       # one ramp, 25 to 85 C
    cov = prepare(_temperature_record(lambda t: 25.0 + r * t, n), 0.01).temperature_coverage()
    # each held-out segment starts a gap after its training window (0.2 segment = many times the 0.5 K margin)
    assert cov["heldout_outside_fraction"] == 1.0
    assert all(f["test_outside_fraction"] == 1.0 for f in cov["folds"])
    # the farthest held-out block: the segment plus its gap beyond the last training block (to a block)
    seg = n / N_SEGMENTS
    assert abs(cov["heldout_outside_max_K"] - r * seg * (1 + GAP_FRACTION)) < r * BLOCK_S
    assert abs(cov["record_C"][0] - 25.0) < r * BLOCK_S and abs(cov["record_C"][1] - 85.0) < r * BLOCK_S
    # a cycled oven: every fold trains on whole cycles and is tested inside their range
    cyc = prepare(_temperature_record(lambda t: 25.0 + 30.0 * np.sin(2 * np.pi * t / 1200.0), n), 0.01)
    cov = cyc.temperature_coverage()
    assert cov["heldout_outside_fraction"] == 0.0 and cov["heldout_outside_max_K"] < 0.5


def test_folds_are_forward_chained_with_a_gap():
    from fmvmg_sim.diagnosis.data import BLOCK_S, GAP_FRACTION, N_FOLDS, N_SEGMENTS
    n = 7200
    prep = prepare(_record(n=n), 0.01)
    folds = prep.folds()
    tb = prep.block_time_s()
    seg = n / N_SEGMENTS
    assert len(folds) == N_FOLDS
    for k, f in enumerate(folds):
        # training ends a gap before the held-out segment: nothing random, nothing after it
        assert tb[f["train"]].max() < f["test_start_s"] - GAP_FRACTION * seg
        assert tb[f["test"]].min() >= f["test_start_s"] and tb[f["test"]].max() <= f["test_end_s"]
        assert not (f["train"] & f["test"]).any()
        if k:  # the window expands and the held-out segments tile the end of the record
            assert f["train"].sum() > folds[k - 1]["train"].sum()
            assert f["test_start_s"] == folds[k - 1]["test_end_s"]
    assert abs(folds[-1]["test_end_s"] - n) < 1e-6
    assert abs(folds[0]["test_start_s"] - n * (N_SEGMENTS - N_FOLDS) / N_SEGMENTS) < 1e-6
    # the first fold trains on what precedes its segment and gap: 1.8 of 5 segments
    first = (N_SEGMENTS - N_FOLDS - GAP_FRACTION) / N_SEGMENTS
    assert abs(folds[0]["train"].mean() - first) < BLOCK_S / n
