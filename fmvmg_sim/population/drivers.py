"""Which tolerances drive the failures: a failure-rate split per knob, with rank correlations beside it.

For each knob the drawn deviations (uniform on ``[-t, +t]``) are cut into :data:`N_BINS` equal-width, hence
equally likely, bins, and the failure rate is counted in each. A knob drives the failures as much as the
failure rate depends on where in its tolerance the unit sits: its score is the largest bin failure rate minus
the smallest. The split needs no model, sees one-sided causes (failures at one end) and two-sided ones (a figure
growing with ``|x|``, failures at both ends) alike, and reads in the units a yield is spoken of. Beside it, the
Spearman rank correlation of each knob with each limited figure says in which direction and how monotonically
a knob moves that figure. A logistic regression of pass/fail on all knobs was not chosen: it needs about ten
failures per knob to be stable and diverges when a knob separates passes from failures, which is exactly
the case of a dominant tolerance.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import spearmanr

#: Equal-width bins of each knob's tolerance for the failure-rate split.
N_BINS = 4


def failure_split(x: np.ndarray, tolerance: float, failed: np.ndarray, n_bins: int = N_BINS) -> tuple:
    """Failure rate in equal-width bins of a knob's tolerance.

    Parameters
    ----------
    x : ndarray
        The knob's deviation in each unit.
    tolerance : float
        Its tolerance (the bins cover ``[-tolerance, +tolerance]``).
    failed : ndarray of bool
        Whether each unit failed the spec.
    n_bins : int, optional

    Returns
    -------
    rates : ndarray
        Failure rate per bin (NaN in an empty bin).
    counts : ndarray of int
        Units per bin.
    """
    edges = np.linspace(-tolerance, tolerance, n_bins + 1)
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, n_bins - 1)
    counts = np.bincount(idx, minlength=n_bins)
    fails = np.bincount(idx, weights=failed.astype(float), minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        rates = np.where(counts > 0, fails / np.maximum(counts, 1), np.nan)
    return rates, counts


def rank_correlation(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman rank correlation over the units where both are finite (NaN with fewer than 3).

    Parameters
    ----------
    x, y : ndarray

    Returns
    -------
    float
    """
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3 or np.ptp(x[ok]) == 0 or np.ptp(y[ok]) == 0:
        return float("nan")
    return float(spearmanr(x[ok], y[ok]).statistic)


def drivers(knobs: dict, draws: np.ndarray, figures: dict, failed: np.ndarray, limited: list) -> list:
    """Knobs ranked by how much they drive the failures.

    Parameters
    ----------
    knobs : dict
        ``{knob name: tolerance}``, in the column order of ``draws``.
    draws : ndarray, shape (units, knobs)
        Each unit's deviations.
    figures : dict
        ``{figure: ndarray over units}``.
    failed : ndarray of bool
        Whether each unit failed the spec.
    limited : list of str
        The figures the spec limits (the correlations reported).

    Returns
    -------
    list of dict
        One row per knob, highest ``score`` first (ties by the largest ``|rho|`` with a limited figure):
        ``knob``, ``tolerance``, ``score`` (failure-rate spread across the bins), ``failure_rate_by_bin``,
        ``units_by_bin``, ``bin_edges`` and ``spearman`` (``{figure: rho}``).
    """
    rows = []
    for j, (name, tol) in enumerate(knobs.items()):
        x = draws[:, j]
        rates, counts = failure_split(x, tol, failed)
        seen = rates[np.isfinite(rates)]
        score = float(seen.max() - seen.min()) if seen.size else 0.0
        rho = {f: rank_correlation(x, np.asarray(figures[f], dtype=float)) for f in limited}
        rows.append(dict(knob=name, tolerance=float(tol), score=score, failure_rate_by_bin=rates.tolist(),
                         units_by_bin=counts.tolist(), bin_edges=np.linspace(-tol, tol, N_BINS + 1).tolist(),
                         spearman=rho))
    best_rho = [max((abs(r) for r in row["spearman"].values() if np.isfinite(r)), default=0.0) for row in rows]
    order = sorted(range(len(rows)), key=lambda i: (-rows[i]["score"], -best_rho[i]))
    return [rows[i] for i in order]
