"""Scalar random-walk KF: steady-state gain = discrete Riccati solution; fast path = plain loop."""

import math

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from fmvmg_sim.compensation.kalman import ScalarKalman, cutoff_Hz, noise_variances, steady_state_gain


@pytest.mark.parametrize("q, r", [(1e-2, 1.0), (1e-6, 1.0), (2.5e-9, 7.7e-4), (3.0, 0.5)])
def test_steady_gain_equals_dare(q, r):
    p = solve_discrete_are(np.array([[1.0]]), np.array([[1.0]]), np.array([[q]]), np.array([[r]]))[0, 0]
    assert steady_state_gain(q, r) == pytest.approx(p / (p + r), rel=1e-9)
    kf = ScalarKalman(q, r)
    if q / r > 1e-7:
        assert kf.gains(10**6)[-1] == pytest.approx(kf.steady_gain, rel=1e-8)


def test_fast_filter_equals_plain_loop():
    rng = np.random.default_rng(0)
    z = np.cumsum(0.01 * rng.standard_normal(5000)) + rng.standard_normal(5000)
    q, r = 1e-4, 1.0
    kf = ScalarKalman(q, r)
    x, p, ref = z[0], r, [z[0]]
    for zk in z[1:]:
        pp = p + q
        k = pp / (pp + r)
        x += k * (zk - x)
        p = (1 - k) * pp
        ref.append(x)
    np.testing.assert_allclose(kf.filter(z), ref, rtol=0, atol=1e-9)


def test_cutoff_and_variances():
    k = 0.1
    assert cutoff_Hz(k, 100.0) == pytest.approx(-100 * math.log(0.9) / (2 * math.pi))
    q, r = noise_variances(0.03, 1e-4, 100.0)
    assert r == pytest.approx(0.03**2 * 100) and q == pytest.approx(1e-8 / 100)
    assert noise_variances(0.03, None, 100.0, accel_rms_dps2=2.0)[0] == pytest.approx(4e-4)

