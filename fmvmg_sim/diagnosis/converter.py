"""A coarse converter as part of the scoring model: the expected staircase of a block mean.

A slowly varying output ``x`` read through a quantiser of step ``L`` whose per-sample noise ``tau`` is much
smaller than ``L`` is a staircase: a block far from a step shows one level whatever ``x`` does inside it, and a
block at a step shows the share of its samples above the threshold, which places ``x`` to a small fraction of
``L``. A smooth model scored against such a channel with a floor of ``L / sqrt(12)`` (the staircase's rms) sees
neither: a candidate that moves a step to the right time gains little, and gains come only from blocks where the
level crosses. Passing each prediction through the converter scores those crossings directly.

Each block mean is modelled as ``mean_i Q(mu + d + e_i)`` over its ``n`` samples, ``e_i ~ N(0, tau^2)``
independent (the white noise that dithers the quantiser) and ``d ~ N(0, tau_c^2)`` common to the block (the
slow noise, the model floors and the prediction's own uncertainty). Its mean and variance are exact under that
model; the mean is the staircase smoothed by ``sqrt(tau^2 + tau_c^2)``, and where ``tau_c`` passes half a step
the two moments are those of the smooth prediction, with variance ``tau_c^2 + (tau^2 + L^2/12) / n``.

Each block is then scored with a misread mixture (:func:`misread_nll`), so that a model error of a step on a
plateau costs a bounded amount. The white noise ``tau`` is read off the null replicates
(:func:`~.null.converter_model`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

#: The block-common offset is integrated over +- this many of its sds.
GRID_HALF_WIDTH = 6.0
#: Most grid points of that integral (spacing at most half the per-sample noise below it).
GRID_MAX = 241
#: Blocks per chunk of the integral (memory).
CHUNK = 512
#: The converter model is used when the dither leaves this much of the staircase's fundamental
#: (``exp(-2 pi^2 tau^2 / L^2)``); below it the quantiser is transparent and the smooth model is exact.
ACTIVE_MIN = 1e-3
#: Levels each side of the nearest one summed over, in units of the per-sample noise (plus one).
LEVEL_SPAN_SIGMA = 6.0
#: A block whose common offset sd exceeds this many steps sees no staircase: its fundamental is attenuated by
#: ``exp(-2 pi^2 0.5^2)`` (0.007), below 1e-3 of a step in the mean, and the smooth moments hold there.
SMOOTH_ABOVE_STEPS = 0.5
#: Share of blocks whose level the model may misread (a model error of about a step), the weight of the wide
#: part of each block's density (:func:`misread_nll`).
MISREAD = 0.05
#: Least sd of a block mean, in steps.
VAR_FLOOR_STEPS = 1e-3


@dataclass(frozen=True)
class Converter:
    """The converter one channel is read through.

    Attributes
    ----------
    lsb_V : float
        Step of the lattice (the record's own).
    tau_V : float
        Per-sample white noise before the quantiser.
    slow_V : float
        Block-level slow noise before the quantiser (sd of a noise-only block mean about the model).
    offset_V : float
        Where the lattice passes, ``offset_V + k * lsb_V`` (an offset added after the converter shifts it).
    """

    lsb_V: float
    tau_V: float
    slow_V: float
    offset_V: float = 0.0


def staircase_visible(lsb_V: float, tau_V: float) -> bool:
    """Whether a quantiser of step ``lsb_V`` dithered by ``tau_V`` leaves a staircase worth modelling.

    Parameters
    ----------
    lsb_V, tau_V : float

    Returns
    -------
    bool
    """
    if not lsb_V > 0 or not np.isfinite(tau_V):
        return False
    return bool(np.exp(-2.0 * np.pi ** 2 * tau_V ** 2 / lsb_V ** 2) > ACTIVE_MIN)


def staircase_moments(mu: np.ndarray, lsb: float, tau: float, tau_c: np.ndarray,
                      n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of a block mean of quantised samples (module docstring).

    Parameters
    ----------
    mu : ndarray, shape (m,)
        Predicted block level before the quantiser.
    lsb : float
        Quantiser step (> 0).
    tau : float
        Per-sample white noise.
    tau_c : ndarray, shape (m,)
        Block-common offset sd.
    n : ndarray, shape (m,)
        Samples per block.

    Returns
    -------
    mean, var : ndarray
        Shape (m,); ``var > 0``.
    """
    mu = np.asarray(mu, dtype=float)
    tau = max(float(tau), 1e-6 * lsb)
    tau_c = np.broadcast_to(np.asarray(tau_c, dtype=float), mu.shape)
    n = np.maximum(np.broadcast_to(np.asarray(n, dtype=float), mu.shape), 1.0)
    out_m = mu.copy()
    out_v = tau_c ** 2 + (tau ** 2 + lsb ** 2 / 12.0) / n
    stair = np.isfinite(mu) & (tau_c <= SMOOTH_ABOVE_STEPS * lsb)
    if stair.any():
        m, v = _stair(mu[stair], lsb, tau, tau_c[stair], n[stair])
        out_m[stair], out_v[stair] = m, v
    return out_m, np.where(np.isfinite(mu), out_v, np.nan)


def _level_probs(u: np.ndarray, lev: np.ndarray, s: float) -> np.ndarray:
    """P(the quantiser reads level ``lev``) for inputs ``u`` (in steps, about the nearest level) with noise ``s``."""
    d = lev - u[..., None]
    return ndtr((d + 0.5) / s) - ndtr((d - 0.5) / s)


def _stair(mu, lsb, tau, tau_c, n):
    """:func:`staircase_moments` on blocks where the staircase shows (finite ``mu``).

    The mean and the per-sample second moment are closed-form (the two noises add); the block-common part of
    the variance, ``E_d[g(mu + d)^2]`` with ``g`` the staircase dithered by ``tau`` alone, is a quadrature on a
    grid finer than ``tau`` (the integrand has steps of width ``tau``)."""
    j0 = np.round(mu / lsb)
    u0 = mu / lsb - j0
    s = tau / lsb
    sc = tau_c / lsb
    s_eff = np.sqrt(s * s + sc * sc)
    span = int(np.ceil(GRID_HALF_WIDTH * (np.max(sc) + s) + 1.0))
    lev = np.arange(-span, span + 1, dtype=float)
    pe = ndtr((lev[None, :] - u0[:, None] + 0.5) / s_eff[:, None]) - ndtr((lev[None, :] - u0[:, None] - 0.5)
                                                                          / s_eff[:, None])
    mean = pe @ lev
    m2 = pe @ lev ** 2
    npts = int(np.clip(np.ceil(2 * GRID_HALF_WIDTH * np.max(sc) / (0.5 * s)) + 1, 9, GRID_MAX))
    z = np.linspace(-GRID_HALF_WIDTH, GRID_HALF_WIDTH, npts)
    w = np.exp(-0.5 * z * z)
    w /= w.sum()
    eg2 = np.empty_like(mean)
    for a in range(0, len(mu), CHUNK):
        b = slice(a, a + CHUNK)
        x = u0[b, None] + sc[b, None] * z[None, :]
        g = _level_probs(x, lev, s) @ lev
        eg2[b] = (g * g) @ w
    var = np.clip((1.0 - 1.0 / n) * eg2 + m2 / n - mean ** 2, 0.0, None)
    # a block far from every step has (almost) no variance: floor it so that one block cannot claim
    # unbounded precision
    var = np.maximum(var, VAR_FLOOR_STEPS ** 2)
    return (j0 + mean) * lsb, var * lsb ** 2


def misread_nll(y: np.ndarray, mean: np.ndarray, var: np.ndarray, lsb: float, scale: np.ndarray) -> np.ndarray:
    """Negative log-density of block means ``y``, in units of ``scale``, under the converter's moments.

    A mixture: weight ``1 - MISREAD`` on ``N(mean, var)``, ``MISREAD`` on the same widened by half a step
    (the model placing a step a block early or late). One misread block then costs about
    ``log(1 / MISREAD) + log(lsb / (2 sqrt(var)))`` nats rather than ``lsb^2 / (2 var)``.

    Parameters
    ----------
    y, mean, var : ndarray
    lsb : float
    scale : ndarray
        The scoring sigma (the density is per unit of ``y / scale``, as the smooth channels' is).

    Returns
    -------
    ndarray
        NaN where ``y`` or ``mean`` is; +inf where the prediction is so far off that neither part has a density.
    """
    var = np.asarray(var, dtype=float)
    wide = var + 0.25 * lsb ** 2
    with np.errstate(over="ignore", invalid="ignore"):
        d2 = (np.asarray(y, dtype=float) - mean) ** 2
        a = np.log(1.0 - MISREAD) - 0.5 * np.log(2 * np.pi * var) - 0.5 * d2 / var
        b = np.log(MISREAD) - 0.5 * np.log(2 * np.pi * wide) - 0.5 * d2 / wide
        out = -(np.logaddexp(a, b) + np.log(scale))
    return np.where(np.isneginf(a) & np.isneginf(b), np.inf, out)


def _p_same_level(s: float) -> float:
    """Chance that two independent samples ``N(u, s^2)`` (in steps) read the same level, ``u`` uniform."""
    u = np.linspace(0.0, 1.0, 41)[:-1] + 0.0125
    K = int(np.ceil(6.0 * s)) + 2
    lev = np.arange(-K, K + 1, dtype=float)
    p = _level_probs(u, lev, s)
    return float(np.mean(np.sum(p * p, axis=1)))


def lattice_noise(x_V: np.ndarray, lsb_V: float) -> float:
    """Per-sample white noise of a slowly varying signal read through a quantiser of step ``lsb_V``.

    The robust spread of first differences is useless on a lattice (its median is a whole step or zero). The
    share of consecutive samples that read the same level is not: for white noise of sd ``s`` steps about a
    mean that wanders over the lattice it is ``P(s) = E_u sum_j p_j(u)^2``, decreasing in ``s``, and is
    solved for ``s`` (rate-table steps and other jumps are too rare to move it).

    Parameters
    ----------
    x_V : ndarray
        Samples on the lattice.
    lsb_V : float
        The lattice step (> 0).

    Returns
    -------
    float
        NaN when fewer than 100 finite differences.
    """
    d = np.diff(np.asarray(x_V, dtype=float))
    d = d[np.isfinite(d)]
    if d.size < 100 or not lsb_V > 0:
        return float("nan")
    same = float(np.mean(np.abs(d) < 0.5 * lsb_V))
    lo, hi = 0.02, 50.0
    if same >= _p_same_level(lo):
        return lo * lsb_V
    if same <= _p_same_level(hi):
        return hi * lsb_V
    for _ in range(40):
        mid = np.sqrt(lo * hi)
        if _p_same_level(mid) > same:
            lo = mid
        else:
            hi = mid
    return float(np.sqrt(lo * hi) * lsb_V)
