"""Sample-entropy classes of VMD modes (fmvmg_sim.compensation.vmd_classes)."""

import numpy as np
import pytest

from fmvmg_sim.compensation.sampen import DRIFT, MIXED, NOISE, WHITE_NOISE_SE
from fmvmg_sim.compensation.vmd import vmd
from fmvmg_sim.compensation.vmd_classes import (
    DRIFT_SE_MAX, NOISE_SE_MIN, calibrate, classify_modes, label_modes, labelled_record, mode_entropies,
    sensitivity,
)


def test_classify_thresholds():
    e = [0.05, DRIFT_SE_MAX - 1e-9, DRIFT_SE_MAX, 0.4, NOISE_SE_MIN, 2.2]
    np.testing.assert_array_equal(classify_modes(e), [DRIFT, DRIFT, MIXED, MIXED, NOISE, NOISE])
    assert 0 < DRIFT_SE_MAX < NOISE_SE_MIN < WHITE_NOISE_SE


@pytest.fixture(scope="module")
def slow_plus_white():
    rng = np.random.default_rng(0)
    n = 3000
    drift = 2.0 * np.sin(2 * np.pi * np.arange(n) / n)  # one slow period
    noise = rng.standard_normal(n)
    return drift, noise, vmd(drift + noise, K=4, alpha=2000, tol=1e-7)


def test_vmd_modes_entropies_and_paper_thresholds(slow_plus_white):
    _, _, res = slow_plus_white
    se = mode_entropies(res.modes)
    assert se[0] < 0.1  # the slow mode is regular
    assert np.all((se[1:] > 0.45) & (se[1:] < 0.8))  # narrow-band noise modes: far below white noise's 2.19
    # the paper's thresholds (noise > 4.2, drift < 2) call every one of them drift
    np.testing.assert_array_equal(classify_modes(se, 4.2, 2.0), [DRIFT] * 4)
    np.testing.assert_array_equal(classify_modes(se), [DRIFT, NOISE, NOISE, NOISE])


def test_label_modes_by_energy_share(slow_plus_white):
    drift, noise, res = slow_plus_white
    shares, labels = label_modes(res, {"signal": np.zeros_like(drift), "drift": drift, "noise": noise})
    total = shares["signal"] + shares["drift"] + shares["noise"]
    np.testing.assert_allclose(total, 1.0)
    assert shares["drift"][0] > 0.9 and np.all(shares["noise"][1:] > 0.99)
    np.testing.assert_array_equal(labels, [DRIFT, NOISE, NOISE, NOISE])


def test_calibrate_finds_separating_thresholds():
    e = np.array([0.02, 0.1, 0.15, 0.3, 0.35, 0.42, 0.6, 0.65, 0.7])
    lab = np.array([DRIFT] * 3 + [MIXED] * 3 + [NOISE] * 3)
    nm, dm, acc = calibrate(e, lab)
    assert acc == 1.0
    assert 0.15 < dm <= 0.3 and 0.42 < nm <= 0.6
    assert np.array_equal(classify_modes(e, nm, dm), lab)


def test_sensitivity_rows():
    e = np.array([0.02, 0.1, 0.2, 0.3, 0.5, 0.6, 0.7])
    lab = np.array([DRIFT, DRIFT, MIXED, MIXED, NOISE, NOISE, NOISE])
    rows = sensitivity(e, lab, noise_min=0.45, drift_max=0.15, rel=0.2)
    assert len(rows) == 9
    nominal = [r for r in rows if r["noise_min"] == 0.45 and r["drift_max"] == 0.15][0]
    assert nominal["changed"] == 0.0 and nominal["accuracy"] == 1.0
    # drift_max 0.18 -> no change; noise_min 0.54 -> the 0.5 mode becomes mixed (1 of 7)
    up = [r for r in rows if r["noise_min"] == 0.54 and r["drift_max"] == 0.15][0]
    assert up["changed"] == pytest.approx(1 / 7) and up["accuracy"] == pytest.approx(6 / 7)


def test_labelled_synthetic_record_at_1Hz():
    r = labelled_record(duration_s=3600.0, fs_Hz=1.0, profile="heating", arw=100.0, seed=0)
    assert r.labels[0] == DRIFT and np.all(r.labels[1:] == NOISE)
    assert r.shares["drift"][0] > 0.8
    np.testing.assert_array_equal(classify_modes(r.entropies), r.labels)
