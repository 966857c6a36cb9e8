"""The literal GA finds known optima; compared with scipy's DE at the same budget."""

import numpy as np
import pytest
from scipy.optimize import differential_evolution

from fmvmg_sim.compensation.ga import ga_budget, genetic_minimize

SHIFT = np.array([1.3, -0.7, 2.1])


def sphere(x):
    return float(np.sum((x - SHIFT) ** 2))


def rastrigin(x):
    z = x - SHIFT[: len(x)]
    return float(10 * len(z) + np.sum(z**2 - 10 * np.cos(2 * np.pi * z)))


def test_shifted_sphere_3d():
    res = genetic_minimize(sphere, [(-5, 5)] * 3, seed=0)
    assert res.n_evals == ga_budget() == 1122
    assert np.max(np.abs(res.x - SHIFT)) < 0.05
    assert res.fun < 1e-3
    assert all(a >= b for a, b in zip(res.history, res.history[1:]))  # elitism: never worse


def test_rastrigin_2d_global_optimum_and_de_baseline():
    bounds = [(-5.12, 5.12)] * 2
    res = genetic_minimize(rastrigin, bounds, seed=3)
    assert np.max(np.abs(res.x - SHIFT[:2])) < 0.05 and res.fun < 0.1
    de = differential_evolution(rastrigin, bounds, popsize=15, maxiter=ga_budget() // 30 - 1, polish=False,
                                seed=3, tol=0)
    assert de.nfev <= ga_budget() + 30
    assert de.fun < 0.1  # both reach the global basin at this budget


def test_integer_genes_and_determinism():
    f = lambda g: (g[0] - 17.0) ** 2 + (g[1] - 0.25) ** 2  # noqa: E731
    a = genetic_minimize(f, [(5, 50), (-1, 1)], integer=[True, False], seed=7, n_generations=15)
    b = genetic_minimize(f, [(5, 50), (-1, 1)], integer=[True, False], seed=7, n_generations=15)
    assert a.x[0] == 17.0 and a.x[1] == pytest.approx(0.25, abs=0.05)
    assert np.array_equal(a.x, b.x) and a.history == b.history


def test_nonfinite_fitness_is_avoided():
    f = lambda g: np.nan if g[0] < 0 else (g[0] - 0.5) ** 2  # noqa: E731
    res = genetic_minimize(f, [(-1, 1)], seed=0, n_generations=10)
    assert res.x[0] == pytest.approx(0.5, abs=0.05)
