"""A literal real/integer genetic algorithm (paper 000 section 3.2, compensation.md section 5).

Generational GA minimising a fitness: tournament selection (size 3), BLX-alpha crossover
(alpha = 0.5, probability 0.8), Gaussian mutation (sigma = 10 % of each gene's range,
probability 1/genes per gene), 2 elites carried over unevaluated, integer genes rounded,
every gene clipped to its bounds. Deterministic for a given seed. The budget is
``pop_size + (n_generations - 1) * (pop_size - n_elite)`` fitness evaluations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np


@dataclass
class GAResult:
    """Outcome of :func:`genetic_minimize`.

    Parameters
    ----------
    x : ndarray
        Best genes found.
    fun : float
        Their fitness.
    n_evals : int
        Fitness evaluations spent.
    history : list of float
        Best fitness after each generation.
    """

    x: np.ndarray
    fun: float
    n_evals: int
    history: list[float] = field(default_factory=list)


def ga_budget(pop_size: int = 30, n_generations: int = 40, n_elite: int = 2) -> int:
    """Fitness evaluations :func:`genetic_minimize` spends with these settings.

    Parameters
    ----------
    pop_size, n_generations, n_elite : int
        GA settings.

    Returns
    -------
    int
    """
    return pop_size + (n_generations - 1) * (pop_size - n_elite)


def genetic_minimize(func: Callable[[np.ndarray], float], bounds: Sequence[tuple[float, float]],
                     integer: Sequence[bool] | None = None, pop_size: int = 30, n_generations: int = 40,
                     tournament: int = 3, crossover_p: float = 0.8, blx_alpha: float = 0.5,
                     mutation_scale: float = 0.1, mutation_p: float | None = None, n_elite: int = 2,
                     seed: int = 0, callback: Callable[[int, float], None] | None = None) -> GAResult:
    """Minimise ``func`` over a box with a generational GA.

    Parameters
    ----------
    func : callable
        Fitness of one gene vector (lower is better).
    bounds : sequence of (low, high)
        Gene bounds.
    integer : sequence of bool, optional
        Which genes are integers (rounded after every variation).
    pop_size, n_generations : int
        Population size and number of generations (the first is the random population).
    tournament : int
        Tournament size of parent selection.
    crossover_p, blx_alpha : float
        Probability of BLX-alpha crossover for a parent pair, and its alpha.
    mutation_scale : float
        Gaussian mutation SD as a fraction of each gene's range.
    mutation_p : float, optional
        Per-gene mutation probability (default 1/genes).
    n_elite : int
        Best individuals copied unchanged into the next generation.
    seed : int
        Random seed.
    callback : callable, optional
        Called as ``callback(generation, best_fitness)`` after each generation.

    Returns
    -------
    GAResult
    """
    rng = np.random.default_rng(seed)

    def evaluate(P):  # a failed or non-finite fitness loses every tournament
        vals = np.array([func(ind) for ind in P], float)
        return np.where(np.isfinite(vals), vals, np.inf)

    lo, hi = np.array(bounds, float).T
    span = hi - lo
    n_genes = len(lo)
    is_int = np.zeros(n_genes, bool) if integer is None else np.asarray(integer, bool)
    p_mut = 1.0 / n_genes if mutation_p is None else mutation_p

    def repair(P):
        P = np.clip(P, lo, hi)
        P[:, is_int] = np.round(P[:, is_int])
        return P

    pop = repair(lo + rng.random((pop_size, n_genes)) * span)
    fit = evaluate(pop)
    n_evals, history = pop_size, [float(fit.min())]
    if callback:
        callback(0, history[-1])
    for gen in range(1, n_generations):
        order = np.argsort(fit, kind="stable")
        elites, elite_fit = pop[order[:n_elite]].copy(), fit[order[:n_elite]].copy()
        n_child = pop_size - n_elite

        def pick():
            idx = rng.choice(pop_size, tournament, replace=False)
            return pop[idx[np.argmin(fit[idx])]]

        children = []
        while len(children) < n_child:
            a, b = pick().copy(), pick().copy()
            if rng.random() < crossover_p:  # BLX-alpha: uniform in the widened parent interval
                cmin, cmax = np.minimum(a, b), np.maximum(a, b)
                ext = blx_alpha * (cmax - cmin)
                a = rng.uniform(cmin - ext, cmax + ext)
                b = rng.uniform(cmin - ext, cmax + ext)
            children.extend([a, b])
        kids = np.array(children[:n_child])
        mask = rng.random(kids.shape) < p_mut
        kids = repair(kids + mask * rng.normal(0.0, 1.0, kids.shape) * mutation_scale * span)
        kid_fit = evaluate(kids)
        n_evals += n_child
        pop, fit = np.vstack([elites, kids]), np.concatenate([elite_fit, kid_fit])
        history.append(float(fit.min()))
        if callback:
            callback(gen, history[-1])
    best = int(np.argmin(fit))
    return GAResult(pop[best].copy(), float(fit[best]), n_evals, history)
