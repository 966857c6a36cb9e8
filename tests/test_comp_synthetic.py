"""Synthetic records: deterministic, components add up, noise levels as specified."""

import numpy as np
import pytest

from fmvmg_sim.compensation.synthetic import DriftParams, make_record, temperature_profile


def test_deterministic_and_components_sum():
    a, comp = make_record(600, 50, "heating", "mixed", seed=3, return_components=True)
    b = make_record(600, 50, "heating", "mixed", seed=3)
    assert np.array_equal(a["rate_dps"], b["rate_dps"])
    np.testing.assert_allclose(sum(comp.values()), a["rate_dps"], atol=1e-15)
    assert np.array_equal(a["rate_true_dps"], comp["true"])
    assert a.metadata["source"] == "synthetic" and len(a) == 30000


def test_white_noise_and_flicker_levels():
    p = DriftParams(rrw_dph_per_rts=0.0)
    _, comp = make_record(2000, 100, "soak", "static", seed=1, params=p, return_components=True)
    # per-sample sigma = N sqrt(fs), in deg/s
    assert np.std(comp["white"]) * 3600 == pytest.approx(100 * 10, rel=0.01)
    # flicker: Allan deviation flat at 0.664 B over a decade of tau
    fl = comp["flicker"] * 3600
    for m in (1000, 4000):
        means = fl[: len(fl) // m * m].reshape(-1, m).mean(1)
        adev = np.sqrt(0.5 * np.mean(np.diff(means) ** 2))
        assert adev == pytest.approx(0.664 * 30, rel=0.25)


@pytest.mark.parametrize("profile, start, end", [("heating", 25, 55), ("cooling", 55, 25), ("soak", 25, 25),
                                                 ("cycle", 25, 25)])
def test_profiles_span_their_limits(profile, start, end):
    t = np.arange(0, 40000.0, 10.0)
    T = temperature_profile(t, profile)
    assert T[0] == pytest.approx(start, abs=0.1) and T[-1] == pytest.approx(end, abs=0.5)
    assert T.min() >= 25 - 1e-9 and T.max() <= 55 + 1e-9


def test_ramp_rate():
    t = np.arange(0, 3600.0, 1.0)
    T = temperature_profile(t, "ramp", ramp_C_per_min=1.0)
    assert np.max(np.abs(np.diff(T))) * 60 == pytest.approx(1.0, rel=1e-6)
