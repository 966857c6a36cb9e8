"""Cuckoo search (fmvmg_sim.compensation.cuckoo) and the equal-budget baselines."""

import math

import numpy as np
import pytest

from fmvmg_sim.compensation.cuckoo import (
    compare_at_budget, cuckoo_search, de_search, grid_search, mantegna_steps,
)


def shifted_sphere(x):
    return float(np.sum((np.asarray(x) - np.array([0.3, -1.2])) ** 2))


def rastrigin(x):
    x = np.asarray(x)
    return float(10 * x.size + np.sum(x ** 2 - 10 * np.cos(2 * np.pi * x)))


def test_finds_known_optimum():
    res = cuckoo_search(shifted_sphere, [(-5, 5), (-5, 5)], budget=1500, seed=0)
    np.testing.assert_allclose(res.x, [0.3, -1.2], atol=0.02)
    assert res.fun < 1e-3 and res.nfev == 1500
    assert res.history == sorted(res.history, reverse=True)  # best-so-far never worsens


def test_multimodal_optimum():
    res = cuckoo_search(rastrigin, [(-5.12, 5.12)] * 2, budget=1500, seed=1)
    assert res.fun < 1.5  # global minimum 0; next local minima are at ~1


def test_deterministic_and_budget_respected():
    a = cuckoo_search(rastrigin, [(-5, 5)] * 2, budget=97, n_nests=10, seed=3)
    b = cuckoo_search(rastrigin, [(-5, 5)] * 2, budget=97, n_nests=10, seed=3)
    assert a.nfev == 97 and a.fun == b.fun and np.array_equal(a.x, b.x)
    calls = []
    cuckoo_search(lambda x: calls.append(x.copy()) or 0.0, [(0, 1), (10, 20)], budget=50, seed=0)
    pts = np.array(calls)
    assert len(pts) == 50 and pts[:, 0].min() >= 0 and pts[:, 1].max() <= 20 and pts[:, 1].min() >= 10


def test_mantegna_step_distribution():
    steps = mantegna_steps(np.random.default_rng(0), (200_000,), beta=1.5)
    # symmetric, heavy-tailed; the median |step| of u/|v|^(2/3) with sigma_u = 0.6966 solves
    # E_v[erf(m |v|^(2/3) / (sigma_u sqrt 2))] = 1/2, i.e. m = 0.6310 (numerical quadrature)
    sigma_u = (math.gamma(2.5) * math.sin(0.75 * math.pi) / (math.gamma(1.25) * 1.5 * 2 ** 0.25)) ** (1 / 1.5)
    assert sigma_u == pytest.approx(0.6966, abs=1e-4)
    assert abs(np.median(steps)) < 0.01
    assert np.median(np.abs(steps)) == pytest.approx(0.6310, rel=0.01)
    assert np.mean(np.abs(steps) > 10) > 1e-3  # a Gaussian of that scale would give ~0


def test_grid_and_de_respect_budget():
    g = grid_search(shifted_sphere, [(-5, 5), (-5, 5)], budget=400)
    assert g.nfev == 400  # 20 x 20
    d = de_search(shifted_sphere, [(-5, 5), (-5, 5)], budget=400, seed=0)
    assert d.nfev <= 400 and d.fun < 1e-3


def test_compare_at_equal_budget():
    out = compare_at_budget(rastrigin, [(-5.12, 5.12)] * 2, budget=400, seed=0)
    assert set(out) == {"cuckoo", "grid", "de"}
    assert all(r.nfev <= 400 for r in out.values())
    # measured at this budget and seed: DE 0.13, cuckoo 3.0, grid 12.0 (20 x 20 grid misses 0)
    assert out["de"].fun < out["cuckoo"].fun < out["grid"].fun


def test_bad_bounds():
    with pytest.raises(ValueError):
        cuckoo_search(shifted_sphere, [(1, 0)], budget=10)
