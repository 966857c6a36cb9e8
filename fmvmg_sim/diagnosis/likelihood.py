"""Gaussian likelihood of block residuals with a slow component, per channel.

Block residuals of a slow record are coloured (flicker, random walk, model floors), so a white
likelihood overstates every improvement. Each channel's normalised residual is modelled as a slow
AR(1) state seen through white noise, ``z_t = x_t + w_t``, ``x_t = rho x_{t-1} + u_t`` (an
ARMA(1,1) process): the flicker floor of a gyro's rate output (tens of deg/h wandering over
thousands of seconds) is the slow state, the white noise the rest. The one-step innovations of the
steady-state Kalman filter, ``e = (1 - rho B) / (1 - rho (1 - K) B) z``, are white with variance
``s^2``; parameters ``(rho, K, s)`` are fitted on the re-simulated null and held fixed to score
held-out blocks. A plain AR(1) is the case ``K = 1``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize
from scipy.signal import lfilter


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


def ar1_nll_terms(z: np.ndarray, rho: float, s: float, K: float | None = None) -> np.ndarray:
    """Per-block negative log-likelihood contributions (NaN where ``z`` is NaN).

    Parameters
    ----------
    z : ndarray
    rho, s : float
    K : float, optional
        Steady-state Kalman gain of the slow-state model; ``None`` or 1 for a plain AR(1).

    Returns
    -------
    ndarray
        Same length as ``z``.
    """
    z = np.asarray(z, dtype=float)
    if K is None or K >= 1.0:
        prev = np.concatenate([[np.nan], z[:-1]])
        e = np.where(np.isfinite(prev), z - rho * prev, z * np.sqrt(max(1 - rho ** 2, 1e-6)))
    else:
        e = innovations(z, rho, K)
    return 0.5 * np.log(2 * np.pi * s * s) + 0.5 * (e / s) ** 2


def innovations(z: np.ndarray, rho: float, K: float) -> np.ndarray:
    """One-step innovations of the slow-state model (NaN blocks carry the prediction, NaN out).

    Parameters
    ----------
    z : ndarray
    rho, K : float

    Returns
    -------
    ndarray
    """
    z = np.asarray(z, dtype=float)
    bad = ~np.isfinite(z)
    e = lfilter([1.0, -rho], [1.0, -rho * (1.0 - K)], np.where(bad, 0.0, z))
    if bad.any():
        e[bad] = np.nan
    return e


def slow_state_fit(series: list) -> tuple[float, float, float]:
    """Maximum-likelihood ``(rho, K, s)`` of the slow-state model, pooled over several series.

    Parameters
    ----------
    series : list of ndarray
        Residual series (NaNs allowed).

    Returns
    -------
    (rho, K, s) : tuple of float
    """
    zs = [np.asarray(z, dtype=float) for z in series if np.isfinite(z).sum() > 10]
    if not zs:
        return 0.0, 1.0, 1.0
    var = float(np.nanmean(np.concatenate([z[np.isfinite(z)] for z in zs]) ** 2))

    def unpack(p):
        rho = 0.9999 / (1 + np.exp(-p[0]))
        q, r = np.exp(p[1]), np.exp(p[2])
        P = _riccati(rho, q, r)
        return rho, P / (P + r), np.sqrt(P + r)

    def obj(p):
        rho, K, s = unpack(p)
        tot = 0.0
        for z in zs:
            e = innovations(z, rho, K)
            ok = np.isfinite(e)
            tot += np.sum(0.5 * np.log(2 * np.pi * s * s) + 0.5 * (e[ok] / s) ** 2)
        return tot
    best = None
    for rho0, frac in ((0.5, 0.5), (0.98, 0.1), (0.995, 0.02)):
        p0 = np.array([np.log(rho0 / (0.9999 - rho0)), np.log(max(var * frac * (1 - rho0 ** 2), 1e-12)),
                       np.log(max(var * (1 - frac), 1e-12))])
        r = minimize(obj, p0, method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-3, "maxiter": 400})
        if best is None or r.fun < best.fun:
            best = r
    rho, K, s = unpack(best.x)
    return float(rho), float(K), float(max(s, 1e-9))


def _riccati(rho: float, q: float, r: float) -> float:
    """Steady prior variance P of the scalar filter: P = rho^2 (P - P^2 / (P + r)) + q."""
    # P^2 + P (r (1 - rho^2) - q) - q r = 0
    b = r * (1 - rho * rho) - q
    return float(0.5 * (-b + np.sqrt(b * b + 4 * q * r)))


def _terms(z: np.ndarray, p: tuple) -> np.ndarray:
    """NLL terms for ``p = (rho, s)`` (AR(1)) or ``(rho, K, s)`` (slow state plus white noise)."""
    if len(p) == 3:
        return ar1_nll_terms(z, p[0], p[2], p[1])
    return ar1_nll_terms(z, *p)


def nll(Z: np.ndarray, params: list[tuple[float, float]]) -> np.ndarray:
    """Per-block NLL summed over channels (columns of ``Z``; NaN columns skipped).

    Parameters
    ----------
    Z : ndarray, shape (n, C)
        Normalised residuals.
    params : list of (rho, s) or (rho, K, s)
        One per column (None to skip).

    Returns
    -------
    ndarray, shape (n,)
    """
    out = np.zeros(len(Z))
    for c, p in enumerate(params):
        if p is None:
            continue
        out += np.nan_to_num(_terms(Z[:, c], p))
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
            out[:, c] = np.nan_to_num(_terms(Z[:, c], p))
    return out


def expected_gain(dZ: np.ndarray, params: list) -> float:
    """Held-out NLL gain expected of a candidate over its baseline were the candidate true.

    With the truth equal to the candidate's prediction, the baseline's normalised residual is the
    prediction change ``dZ`` plus noise; for a Gaussian model with a common noise process the expected
    NLL difference is the Kullback-Leibler divergence, half the squared whitened innovations of ``dZ``.

    Parameters
    ----------
    dZ : ndarray, shape (n, C)
        Baseline minus candidate normalised residual (NaN counts as no change).
    params : list of (rho, s) or (rho, K, s)
        Noise model per column (None to skip).

    Returns
    -------
    float
        Nats (>= 0).
    """
    dZ = np.nan_to_num(np.asarray(dZ, dtype=float))
    return float(np.sum(nll_by_channel(dZ, params) - nll_by_channel(np.zeros_like(dZ), params)))


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


def block_length(d: np.ndarray) -> int:
    """Block length for a bootstrap of the mean of ``d``, from its own autocorrelation.

    Twice the first lag where the sample autocorrelation falls inside its +-2/sqrt(n) band (the
    flat-top lag-window rule of Politis and White), at least ``2 n^(1/3)`` and at most ``n/3``. A
    gain series that follows slow noise (flicker, rate random walk in a ramp) is correlated over
    far more than the ``n^(1/3)`` rule assumes, and short blocks would make its interval too narrow.

    Parameters
    ----------
    d : ndarray
        Finite values.

    Returns
    -------
    int
    """
    n = len(d)
    lo = max(2, int(round(2 * n ** (1 / 3))))
    hi = max(lo, n // 3)
    x = d - d.mean()
    v = float(x @ x)
    if v <= 0:
        return lo
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[:n] / v
    band = 2.0 / np.sqrt(n)
    inside = np.flatnonzero(np.abs(acf[1:hi + 1]) < band)
    m = int(inside[0]) + 1 if inside.size else hi
    return int(min(max(2 * m, lo), hi))


def block_bootstrap_ci(d: np.ndarray, n_boot: int = 300, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Circular block bootstrap confidence interval of the mean of a serially correlated series.

    Blocks of :func:`block_length` start anywhere and wrap from the end to the start (Politis and Romano's
    circular block bootstrap), so every value is drawn with the same probability and the resampled means
    centre on the sample mean. A moving-block bootstrap, whose blocks must fit inside the series, draws the first
    and last ``L - 1`` values less often; with blocks up to a third of the series long (a gain series that
    follows slow noise), its interval then centres on the middle of the record and can exclude the mean itself.

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
    L = block_length(d)
    nb = int(np.ceil(n / L))
    rng = np.random.default_rng(seed)
    starts = rng.integers(0, n, size=(n_boot, nb))
    idx = ((starts[:, :, None] + np.arange(L)) % n).reshape(n_boot, -1)[:, :n]
    means = d[idx].mean(axis=1)
    a = (1 - level) / 2
    return float(np.quantile(means, a)), float(np.quantile(means, 1 - a))
