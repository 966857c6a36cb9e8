"""Gaussian AR(1) likelihood of block residuals, per channel.

Block residuals of a slow record are coloured (flicker, random walk, model floors), so a white
likelihood overstates every improvement. Each channel's normalised residual ``z`` is modelled as
``z_t = rho z_{t-1} + e_t``, ``e ~ N(0, s^2)``; ``rho`` and ``s`` are fitted on training data and
then held fixed to score held-out blocks.
"""

from __future__ import annotations

import numpy as np


def ar1_fit(z: np.ndarray) -> tuple[float, float]:
    """AR(1) coefficient and innovation standard deviation of a residual series (NaNs skipped).

    Parameters
    ----------
    z : ndarray

    Returns
    -------
    rho : float
        In [0, 0.999].
    s : float
        Innovation standard deviation (> 0).
    """
    z = np.asarray(z, dtype=float)
    a, b = z[:-1], z[1:]
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        v = np.nanvar(z) if np.isfinite(z).sum() > 1 else 1.0
        return 0.0, float(np.sqrt(max(v, 1e-12)))
    rho = float(np.clip(np.dot(a[ok], b[ok]) / max(np.dot(a[ok], a[ok]), 1e-300), 0.0, 0.999))
    e = b[ok] - rho * a[ok]
    return rho, float(max(np.sqrt(np.mean(e ** 2)), 1e-9))


def ar1_nll_terms(z: np.ndarray, rho: float, s: float) -> np.ndarray:
    """Per-block negative log-likelihood contributions (NaN where undefined).

    Parameters
    ----------
    z : ndarray
    rho, s : float

    Returns
    -------
    ndarray
        Same length as ``z``; the first block and blocks after a NaN use the stationary variance.
    """
    z = np.asarray(z, dtype=float)
    prev = np.concatenate([[np.nan], z[:-1]])
    e = np.where(np.isfinite(prev), z - rho * prev, z * np.sqrt(max(1 - rho ** 2, 1e-6)))
    return 0.5 * np.log(2 * np.pi * s * s) + 0.5 * (e / s) ** 2


def nll(Z: np.ndarray, params: list[tuple[float, float]]) -> np.ndarray:
    """Per-block NLL summed over channels (columns of ``Z``; NaN columns skipped).

    Parameters
    ----------
    Z : ndarray, shape (n, C)
        Normalised residuals.
    params : list of (rho, s)
        One per column (None to skip).

    Returns
    -------
    ndarray, shape (n,)
    """
    out = np.zeros(len(Z))
    for c, p in enumerate(params):
        if p is None:
            continue
        t = ar1_nll_terms(Z[:, c], *p)
        out += np.nan_to_num(t)
    return out


def nll_by_channel(Z: np.ndarray, params: list[tuple[float, float]]) -> np.ndarray:
    """Per-block NLL of each channel (zero for skipped channels).

    Parameters
    ----------
    Z : ndarray, shape (n, C)
    params : list of (rho, s) or None

    Returns
    -------
    ndarray, shape (n, C)
    """
    out = np.zeros(Z.shape)
    for c, p in enumerate(params):
        if p is not None:
            out[:, c] = np.nan_to_num(ar1_nll_terms(Z[:, c], *p))
    return out


def fit_params(Z: np.ndarray) -> list:
    """AR(1) parameters of every column with finite data.

    Parameters
    ----------
    Z : ndarray, shape (n, C)

    Returns
    -------
    list of (rho, s) or None
    """
    return [ar1_fit(Z[:, c]) if np.isfinite(Z[:, c]).sum() > 3 else None for c in range(Z.shape[1])]


def block_bootstrap_ci(d: np.ndarray, n_boot: int = 300, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Moving-block bootstrap confidence interval of the mean of a serially correlated series.

    Parameters
    ----------
    d : ndarray
    n_boot : int, optional
    level : float, optional
    seed : int, optional

    Returns
    -------
    (lo, hi) : tuple of float
    """
    d = np.asarray(d, dtype=float)
    d = d[np.isfinite(d)]
    n = len(d)
    if n < 4:
        return (float("nan"), float("nan"))
    L = max(2, int(round(n ** (1 / 3) * 2)))
    nb = int(np.ceil(n / L))
    rng = np.random.default_rng(seed)
    starts = rng.integers(0, n - L + 1, size=(n_boot, nb))
    idx = (starts[:, :, None] + np.arange(L)).reshape(n_boot, -1)[:, :n]
    means = d[idx].mean(axis=1)
    a = (1 - level) / 2
    return float(np.quantile(means, a)), float(np.quantile(means, 1 - a))
