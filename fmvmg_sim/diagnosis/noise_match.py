"""The null's auxiliary-channel noise, matched to the record's own.

The null replicates (:func:`.localize.null_records`) are the calibrated nominal device simulated with its
noise. Its auxiliary channels (quadrature, drive amplitude, AGC effort, drive frequency) carry the noise of
the simulated loop only; a measured unit's carry its data acquisition's noise as well, white and 1/f, which
no device file states. Compared with a quieter null, every auxiliary channel of a real record would look
like a gap.

The record says how much noise each channel carries, on short spans where a deterministic signature of
minutes to hours barely moves a difference of block means: the two-sample (Allan) variance of the
normalised block residual over spans of 1 to :data:`SPANS` blocks, each read robustly (the median absolute
difference, so that ramp corners and steps, a few per cent of the spans, do not count), is fitted as white
noise (``a / m``) plus a 1/f plateau (``b``). The same is read off each replicate, and each replicate
receives the difference (white and 1/f noise of the missing levels), so that it carries the record's noise.
The rate output is left as simulated: its noise is the device's physics (the phase flicker follows the
quadrature), and extra flicker there is the ``flicker_noise`` effect.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from ..noise import flicker
from .forward import IRATE

#: Spans (in blocks) over which the short-term noise is read.
SPANS = (1, 2, 4, 8, 16, 32)
#: Normal-consistent scale of the median absolute deviation.
_MAD = 1.4826


def short_term_noise(z: np.ndarray) -> tuple[float, float]:
    """White level and 1/f plateau of a normalised block residual, from robust two-sample variances.

    Parameters
    ----------
    z : ndarray
        Block residual in block sigmas (NaN blocks skipped).

    Returns
    -------
    white : float
        Variance per block of its white part (1 for white noise at the block sigma).
    plateau : float
        Allan variance of its 1/f part (flat in the span).
    """
    x = np.asarray(z, dtype=float)
    x = x[np.isfinite(x)]
    rows, vals = [], []
    c = np.concatenate([[0.0], np.cumsum(x)])
    for m in SPANS:
        if len(x) < 8 * m:
            break
        means = (c[m:] - c[:-m]) / m
        d = means[m:] - means[:-m]
        avar = 0.5 * (_MAD * float(np.median(np.abs(d - np.median(d))))) ** 2
        # each span weighted by its own size (a relative fit)
        rows.append(np.array([1.0 / m, 1.0]) / max(avar, 1e-300))
        vals.append(1.0)
    if len(rows) < 2:
        v = float(np.var(x)) if len(x) > 1 else 0.0
        return v, 0.0
    coef, _ = nnls(np.array(rows), np.array(vals))
    return float(coef[0]), float(coef[1])


def matched_noise(Z_record: np.ndarray, Z_nulls: list, S: np.ndarray, seed: int) -> list:
    """The noise each null replicate lacks in each auxiliary channel, in channel units per block.

    Parameters
    ----------
    Z_record : ndarray, shape (n, C)
        The record's normalised block residual against its calibrated model.
    Z_nulls : list of ndarray, shape (n, C)
        Each replicate's, against its own calibration on the same blocks.
    S : ndarray, shape (n, C)
        The block sigma (the normalisation).
    seed : int

    Returns
    -------
    list of ndarray, shape (n, C)
        Per replicate, noise to add to its block means (zero in the rate channel and where nothing lacks).
    """
    n, C = Z_record.shape
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x6E6F6973]))
    out = [np.zeros((n, C)) for _ in Z_nulls]
    for c in range(C):
        if c == IRATE or not np.isfinite(Z_record[:, c]).any():
            continue
        w_rec, f_rec = short_term_noise(Z_record[:, c])
        s = np.nan_to_num(S[:, c])
        for k, Zn in enumerate(Z_nulls):
            w_n, f_n = short_term_noise(Zn[:, c])
            dw, df = max(w_rec - w_n, 0.0), max(f_rec - f_n, 0.0)
            add = np.sqrt(dw) * rng.standard_normal(n)
            if df > 0:
                add = add + _flicker_blocks(n, df, rng)
            out[k][:, c] = add * s
    return out


def _flicker_blocks(n: int, plateau: float, rng: np.random.Generator) -> np.ndarray:
    """1/f noise at one sample per block whose Allan variance plateau is ``plateau`` (``sigma^2 = 2 ln2 h``)."""
    return flicker(n, 1.0, plateau / (2.0 * np.log(2.0)), rng)
