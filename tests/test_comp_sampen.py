"""Sample entropy: the white-noise value, monotone classes, threshold calibration."""

import numpy as np
import pytest

from fmvmg_sim.compensation import sampen
from fmvmg_sim.compensation.sampen import DRIFT, MIXED, NOISE


def test_white_noise_matches_theory():
    assert sampen.WHITE_NOISE_SE == pytest.approx(2.1851, abs=1e-4)
    x = np.random.default_rng(1).standard_normal(20000)
    se, nseg = sampen.sample_entropy(x)
    assert nseg == 1
    assert se == pytest.approx(sampen.WHITE_NOISE_SE, rel=0.02)


def test_sine_is_regular_and_long_signals_use_segments():
    x = np.sin(2 * np.pi * np.arange(100_000) / 100.0)
    se, nseg = sampen.sample_entropy(x)
    assert nseg == 5 and se < 0.25


def test_classes_are_monotone_even_when_entropies_are_not():
    ent = np.array([2.0, 0.5, 1.9, 0.3, 0.05, 0.6, 0.01])
    raw = sampen.raw_classes(ent, 1.5, 0.1)
    assert raw.tolist() == [NOISE, MIXED, NOISE, MIXED, DRIFT, MIXED, DRIFT]
    cls = sampen.classify(ent, 1.5, 0.1)
    assert np.all(np.diff(cls) >= 0)
    assert cls.tolist() == [NOISE, MIXED, MIXED, MIXED, MIXED, MIXED, DRIFT]  # L1 cost 2; ties keep more mixed


def test_monotone_projection_is_l1_optimal():
    rng = np.random.default_rng(0)
    for _ in range(50):
        raw = rng.integers(0, 3, 6)
        out = sampen.monotone_classes(raw)
        assert np.all(np.diff(out) >= 0)
        best = min(np.abs(raw - np.array([0] * i + [1] * (j - i) + [2] * (6 - j))).sum()
                   for i in range(7) for j in range(i, 7))
        assert np.abs(raw - out).sum() == best


def test_calibration_finds_separating_thresholds():
    ent = [np.array([2.1, 1.6, 0.9, 0.4, 0.05, 0.01]), np.array([2.0, 1.4, 0.7, 0.2, 0.08])]
    lab = [np.array([0, 0, 1, 1, 2, 2]), np.array([0, 0, 1, 1, 2])]
    nm, dm, acc = sampen.calibrate_thresholds(ent, lab)
    assert acc == 1.0
    assert 0.9 < nm <= 1.4 and 0.08 < dm <= 0.2


def test_kdtree_sample_entropy_equals_antropy():
    """antropy is the oracle (test-only): the same value to the last digit."""
    import numpy as np
    antropy = __import__("pytest").importorskip("antropy")
    from fmvmg_sim.compensation.sampen import sampen_kdtree
    rng = np.random.default_rng(11)
    for x in (rng.standard_normal(3000), np.sin(np.arange(3000) * 0.063) + 0.05 * rng.standard_normal(3000)):
        r = 0.2 * x.std()
        assert sampen_kdtree(x, 2, r) == __import__("pytest").approx(antropy.sample_entropy(x, order=2, tolerance=r),
                                                                      rel=1e-12)
