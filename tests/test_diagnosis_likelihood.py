"""The scoring likelihood: slow-state (ARMA(1,1)) noise fitted by maximum likelihood, block bootstrap."""

import numpy as np

from fmvmg_sim.diagnosis.likelihood import block_bootstrap_ci, block_length, innovations, slow_state_fit


def _slow_plus_white(n, rho, q, r, seed):
    rng = np.random.default_rng(seed)
    x = np.zeros(n)
    u = rng.normal(scale=np.sqrt(q), size=n)
    for t in range(1, n):
        x[t] = rho * x[t - 1] + u[t]
    return x + rng.normal(scale=np.sqrt(r), size=n)


def test_slow_state_fit_recovers_kalman_parameters():
    rho, q, r = 0.99, 0.09, 1.0
    z = _slow_plus_white(20000, rho, q, r, 0)
    # steady-state Riccati by hand: P = rho^2 (P - P^2/(P + r)) + q
    P = 1.0
    for _ in range(5000):
        P = rho ** 2 * (P - P * P / (P + r)) + q
    K, s = P / (P + r), np.sqrt(P + r)
    rho_f, K_f, s_f = slow_state_fit([z[:10000], z[10000:]])
    assert abs(rho_f - rho) < 0.005 and abs(K_f - K) / K < 0.15 and abs(s_f - s) / s < 0.03
    e = innovations(z, rho_f, K_f)
    # innovations are white: lag-1 autocorrelation near 0 (the raw series' is ~0.5)
    e = e[100:] - e[100:].mean()
    assert abs(np.dot(e[1:], e[:-1]) / np.dot(e, e)) < 0.03
    zz = z - z.mean()
    assert np.dot(zz[1:], zz[:-1]) / np.dot(zz, zz) > 0.3


def test_white_series_gives_negligible_slow_state():
    z = np.random.default_rng(1).normal(size=8000)
    rho, K, s = slow_state_fit([z])
    assert abs(s - 1.0) < 0.03 and K * rho < 0.1


def test_block_length_grows_with_correlation_and_ci_widens():
    rng = np.random.default_rng(2)
    white = rng.normal(size=600)
    slow = np.convolve(rng.normal(size=700), np.ones(60) / np.sqrt(60), mode="valid")[:600]
    assert block_length(white) <= 2 * round(2 * 600 ** (1 / 3))
    assert block_length(slow) >= 60
    lo_w, hi_w = block_bootstrap_ci(white)
    lo_s, hi_s = block_bootstrap_ci(slow)
    # the interval of the correlated series reflects its ~10 effective samples, not 600
    assert (hi_s - lo_s) > 3 * (hi_w - lo_w)


def test_block_bootstrap_resamples_centre_on_the_mean_whatever_lies_at_the_ends():
    # a slowly varying gain series whose last stretch loses heavily (a fold at the end of a pooled series): every
    # value is drawn equally often, so the resampled means centre on the
    # sample mean (a moving-block bootstrap under-draws the last stretch: its median sits 0.53 widths high)
    rng = np.random.default_rng(3)
    d = np.convolve(rng.normal(size=500), np.ones(40) / np.sqrt(40), mode="valid")[:432] + 175.0
    d[-60:] -= 400.0
    assert block_length(d) >= 100  # blocks of a quarter of the series
    lo, hi = block_bootstrap_ci(d, n_boot=2000)
    median = block_bootstrap_ci(d, n_boot=2000, level=0.0)[0]
    assert lo < d.mean() < hi
    assert abs(median - d.mean()) < 0.05 * (hi - lo)


def test_expected_gain_is_the_kl_divergence():
    from fmvmg_sim.diagnosis.likelihood import ar1_nll_terms, expected_gain

    n, d = 200, 0.3
    # white noise: half the summed squared change
    dz = np.full((n, 1), d)
    assert np.isclose(expected_gain(dz, [(0.0, 1.0)]), 0.5 * n * d * d)
    # AR(1), rho, s: a constant offset is mostly absorbed (first block stationary, then (1 - rho) d)
    rho, s = 0.9, 0.5
    want = 0.5 * ((1 - rho ** 2) * d * d + (n - 1) * ((1 - rho) * d) ** 2) / s ** 2
    assert np.isclose(expected_gain(dz, [(rho, s)]), want)
    # and equals the mean NLL gain a baseline loses to the truth over many noise draws
    rng = np.random.default_rng(1)
    gains = []
    for _ in range(400):
        w = rng.normal(scale=s, size=n)
        z = np.empty(n)
        z[0] = w[0] / np.sqrt(1 - rho ** 2)
        for t in range(1, n):
            z[t] = rho * z[t - 1] + w[t]
        gains.append(np.sum(ar1_nll_terms(z + d, rho, s) - ar1_nll_terms(z, rho, s)))
    assert abs(np.mean(gains) - want) < 4 * np.std(gains) / np.sqrt(len(gains))
    # a skipped channel carries nothing
    assert expected_gain(np.column_stack([dz[:, 0], dz[:, 0]]), [None, (0.0, 1.0)]) == expected_gain(dz, [(0.0, 1.0)])
