"""EMD wrapper: recovers a known sum of tones and a trend; refuses bad input."""

import numpy as np
import pytest

from fmvmg_sim.compensation.emd import MIN_EMD_SAMPLES, emd_decompose, mean_period_s, trend
from fmvmg_sim.errors import InputError


def test_tones_and_trend_are_recovered():
    fs = 100.0
    t = np.arange(0, 60, 1 / fs)
    fast, slow, tr = np.sin(2 * np.pi * 5 * t), 0.5 * np.sin(2 * np.pi * 0.5 * t), 0.05 * t + 0.002 * t**2
    res = emd_decompose(fast + slow + tr, fs)
    assert res.n_imfs == 2
    np.testing.assert_allclose(res.imfs.sum(0) + res.residue, fast + slow + tr, atol=1e-12)
    mid = slice(600, -600)  # away from the spline end effects
    assert np.sqrt(np.mean((res.imfs[0] - fast)[mid] ** 2)) < 0.01
    assert np.sqrt(np.mean((res.imfs[1] - slow)[mid] ** 2)) < 0.01
    assert np.sqrt(np.mean((res.residue - tr)[mid] ** 2)) < 0.01
    np.testing.assert_allclose(res.mean_periods_s(), [0.2, 2.0], rtol=0.05)


def test_monotone_input_is_all_residue():
    x = np.linspace(0.0, 3.0, 1000) ** 2
    res = emd_decompose(x, 10.0)
    assert res.n_imfs == 0 and np.array_equal(res.residue, x)


def test_mean_period_of_a_sine():
    t = np.arange(0, 100, 0.01)
    assert mean_period_s(np.sin(2 * np.pi * 0.25 * t + 0.1), 100.0) == pytest.approx(4.0, rel=0.01)


def test_temperature_trend_is_decimated_and_reported():
    fs = 100.0
    t = np.arange(0, 3600, 1 / fs)
    T_true = 25 + 30 * (1 - np.exp(-t / 900))
    tr, info = trend(t, T_true + 0.01 * np.random.default_rng(0).standard_normal(len(t)), fs)
    assert info["decimation"] == 100 and "block-averaged by 100" in info["notes"][0]
    assert np.max(np.abs(tr - T_true)[6000:-6000]) < 0.05


@pytest.mark.parametrize("x, msg", [(np.zeros(MIN_EMD_SAMPLES - 1), "needs at least"),
                                    (np.r_[np.zeros(500), np.nan], "NaN")])
def test_bad_input_is_an_input_error(x, msg):
    with pytest.raises(InputError, match=msg):
        emd_decompose(x, 100.0)
