"""The coarse converter's scoring model: moments of a block mean of quantised samples, against Monte Carlo."""

import numpy as np
import pytest

from fmvmg_sim.diagnosis.converter import MISREAD, lattice_noise, misread_nll, staircase_moments, staircase_visible


def _monte_carlo(mu, lsb, tau, tau_c, n, draws=200_000, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.normal(0.0, tau_c, draws) if tau_c > 0 else np.zeros(draws)
    x = mu + d[:, None] + rng.normal(0.0, tau, (draws, n))
    y = (np.round(x / lsb) * lsb).mean(axis=1)
    return y.mean(), y.var()


@pytest.mark.parametrize("tau,mu,tau_c", [
    (0.1, 0.3, 0.0),     # plateau, dithered edge: the mean is pulled to the level
    (0.1, 0.45, 0.05),   # at a step
    (0.04, 0.45, 0.1),   # coarse converter, block offset wider than the dither
    (0.04, 0.1, 0.3),    # offset spans a step
    (0.04, 2.2, 0.4),    # far from zero, offset near the smooth limit
])
def test_moments_match_monte_carlo(tau, mu, tau_c):
    m_mc, v_mc = _monte_carlo(mu, 1.0, tau, tau_c, 10)
    m, v = staircase_moments(np.array([mu]), 1.0, tau, np.array([tau_c]), np.array([10]))
    # Monte Carlo sd of the mean is sqrt(v / 2e5) < 2e-3; of the variance about v * sqrt(2 / 2e5)
    assert abs(m[0] - m_mc) < 4e-3 + 0.01 * abs(m_mc)
    assert abs(v[0] - v_mc) < 0.03 * v_mc + 1e-5


def test_plateau_reads_the_level_and_step_reads_the_share_above():
    lsb, tau = 0.01, 3e-4
    m, v = staircase_moments(np.array([0.0132, 0.015]), lsb, tau, np.zeros(2), np.array([10, 10]))
    # on a plateau the block mean is the level itself, not the smooth input
    assert m[0] == pytest.approx(0.01, abs=1e-9) and np.sqrt(v[0]) < 1e-4
    # exactly at a threshold half the samples read each level: mean mid-way, binomial variance p(1-p) L^2 / n
    assert m[1] == pytest.approx(0.015, abs=1e-9)
    assert v[1] == pytest.approx(0.25 * lsb ** 2 / 10, rel=1e-6)


def test_smooth_limit_when_the_block_offset_spans_steps():
    lsb, tau, n = 0.01, 3e-4, 10
    mu = np.linspace(-0.05, 0.05, 7)
    tau_c = np.full(7, 0.6 * lsb)
    m, v = staircase_moments(mu, lsb, tau, tau_c, np.full(7, n))
    assert np.allclose(m, mu)
    assert np.allclose(v, tau_c ** 2 + (tau ** 2 + lsb ** 2 / 12) / n)


def test_staircase_visible_threshold_and_nan():
    assert staircase_visible(0.01, 3e-4)
    assert not staircase_visible(3.05e-4, 8e-4)   # the nominal converter under its own noise
    assert not staircase_visible(0.0, 1e-4)
    assert not staircase_visible(0.01, float("nan"))
    m, v = staircase_moments(np.array([np.nan, 0.0]), 0.01, 3e-4, np.zeros(2), np.ones(2))
    assert np.isnan(m[0]) and np.isnan(v[0]) and np.isfinite(m[1]) and v[1] > 0


def _quantised(noise_V, lsb_V=0.01, n=7200, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(1.0, n + 1.0)
    slow_V = 0.05 * np.sin(2 * np.pi * t / 5000.0)     # a slow drift over several steps
    raw = slow_V + noise_V * rng.standard_normal(n)
    return t, slow_V, raw, np.round(raw / lsb_V) * lsb_V


def _blocks(x, k=10):
    return x[: len(x) // k * k].reshape(-1, k).mean(axis=1)


def test_staircase_likelihood_sees_a_twentieth_of_a_step_that_the_smooth_floor_misses():
    lsb, tau = 0.01, 3e-4
    _, slow, _, q = _quantised(tau, lsb)
    y, mu = _blocks(q), _blocks(slow)
    n = np.full(len(y), 10)
    S = np.full(len(y), lsb / np.sqrt(12))             # the smooth model's floor
    tau_c = np.full(len(y), 1e-5)

    def conv(pred):
        m, v = staircase_moments(pred, lsb, tau, tau_c, n)
        return np.sum(misread_nll(y, m, v, lsb, S))

    def smooth(pred):
        return np.sum(0.5 * ((y - pred) / S) ** 2)

    shift = 0.05 * lsb
    # the smooth model with the staircase floor barely tells the truth from a shift of a twentieth of a step
    # (shift^2 / 2 S^2 = 0.015 nats per block) ...
    assert smooth(mu + shift) - smooth(mu) < 0.02 * len(y)
    # ... the converter's expected staircase tells it twenty times better (the blocks at a step crossing read
    # the share of samples above it)
    assert conv(mu + shift) - conv(mu) > 0.3 * len(y)
    # and the truth scores as the model says: at the step crossings (where the block mean varies) the
    # standardised residual has unit variance; on the plateaus the level is read exactly
    m, v = staircase_moments(mu, lsb, tau, tau_c, n)
    z = (y - m) / np.sqrt(v)
    at_step = v > (0.05 * lsb) ** 2
    assert at_step.sum() > 30 and abs(np.mean(z[at_step] ** 2) - 1.0) < 0.3
    off = np.abs(y - m)[~at_step]
    assert np.mean(off < 0.01 * lsb) > 0.97 and np.all(off < 0.15 * lsb)  # the signal moves inside a block


def test_a_misread_block_costs_a_bounded_amount():
    lsb, S = 0.01, 0.003
    v = np.array([(1e-4) ** 2])
    right = misread_nll(np.array([0.0]), np.array([0.0]), v, lsb, S)
    wrong = misread_nll(np.array([lsb]), np.array([0.0]), v, lsb, S)
    # a Gaussian would charge (L / sd)^2 / 2 = 5000 nats; the mixture charges log(1/MISREAD) + log(L / 2 sd) + ...
    bound = np.log(1 / MISREAD) + np.log(lsb / 2 / 1e-4) + 2.0 + 1.0
    assert 0 < (wrong - right)[0] < bound
    # a model off by far more than any step (a candidate outside its domain) costs without bound, silently
    with np.errstate(all="raise"):
        far = misread_nll(np.array([1e200, np.nan]), np.array([-1e200, 0.0]), np.array([v[0], v[0]]), lsb, S)
    assert far[0] == np.inf and np.isnan(far[1])


@pytest.mark.parametrize("tau_steps", [0.15, 0.5, 0.85, 1.6, 6.0])
def test_lattice_noise_reads_white_noise_through_a_fine_lattice(tau_steps):
    """The null replicates sit on the nominal converter's own lattice: the median absolute difference is a whole
    step whatever the noise, the share of repeated levels gives the noise back."""
    lsb = 3.05e-4
    rng = np.random.default_rng(3)
    t = np.arange(20000)
    x = 0.01 * np.sin(2 * np.pi * t / 7000) + tau_steps * lsb * rng.standard_normal(len(t))
    q = np.round(x / lsb) * lsb
    assert lattice_noise(q, lsb) == pytest.approx(tau_steps * lsb, rel=0.05)
    assert np.isnan(lattice_noise(q[:50], lsb))
