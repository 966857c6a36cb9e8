"""Sample entropy of IMFs and their split into noise / mixed / drift groups (paper 000 section 3.1).

Sample entropy (Richman and Moorman 2000: m = 2, Chebyshev distance, self-matches excluded, the
same n - m templates for lengths m and m + 1) is counted with scipy's KD-tree, O(N log N) time and
O(N) memory, with the tolerance always explicit, r = 0.2 x SD (ddof = 0) of the segment. It gives
antropy's values to the last digit (checked in the tests, where antropy is the oracle); antropy
itself is not imported at run time because it compiles its numba kernels at import (10-50 s). Long signals are cut into 20k-sample
segments and the median is taken (over at most ``max_segments`` evenly spaced ones, so the
cost stays bounded; the count used is returned).

Classes must be monotone in IMF index (noise, then mixed, then drift); :func:`classify`
enforces it. The thresholds were calibrated on labelled synthetic records
(``python benchmarks/compensation.py --calibrate-se``: 1 h at 100 Hz, heating / cooling / ramp,
static and dynamic true rate, 2 seeds, 155 IMFs of ``emd``'s sift; an IMF is labelled
mixed if the true rate holds >= 20 % of it, else noise if white noise holds >= 80 %, else
drift if thermal + flicker + RRW hold >= 80 %, else mixed):

* calibrated: noise if SE >= 0.125, drift if SE < 1.6e-4; 72.9 % of IMFs as labelled
  (x0.5 ... x2 of both thresholds: 70-72 %);
* the starting point 0.8 x 2.185 / 0.1 of compensation.md: 14.8 % (IMF1 of white noise
  has SE ~ 1.5, not 2.19, so nothing is ever "noise");
* static records alone would want 0.010 / 5e-4 (93.5 %), dynamic ones 0.56 / 1.3e-4 (89.7 %):
  one threshold pair cannot serve both, because an IMF's entropy tracks its time scale more
  than its content. The thresholds are tied to ``emd`` 0.8.1 with default sift settings.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erf

NOISE, MIXED, DRIFT = 0, 1, 2
CLASS_NAMES = ("noise", "mixed", "drift")
#: Sample entropy of white Gaussian noise at m = 2, r = 0.2 SD: -ln erf(0.1).
WHITE_NOISE_SE = float(-np.log(erf(0.1)))
#: Calibrated thresholds (see module docstring): noise if SE >= NOISE_SE_MIN, drift if SE < DRIFT_SE_MAX.
NOISE_SE_MIN = 0.125
DRIFT_SE_MAX = 1.6e-4


def sampen_kdtree(x: np.ndarray, m: int, r: float) -> float:
    """Sample entropy ``-ln(A/B)`` of one series by KD-tree pair counting.

    Parameters
    ----------
    x : ndarray
        The series.
    m : int
        Embedding dimension.
    r : float
        Tolerance (absolute, Chebyshev distance).

    Returns
    -------
    float
        Sample entropy; ``inf`` when no template of length m + 1 matches.
    """
    from scipy.spatial import cKDTree

    x = np.asarray(x, float)
    n = len(x)

    def pairs(length: int) -> float:
        emb = np.lib.stride_tricks.sliding_window_view(x, length)[: n - m]
        tree = cKDTree(emb)
        return (tree.count_neighbors(tree, r, p=np.inf) - len(emb)) / 2.0

    B, A = pairs(m), pairs(m + 1)
    if B == 0 or A == 0:
        return float("inf")
    return float(-np.log(A / B))


def sample_entropy(x: np.ndarray, m: int = 2, r_frac: float = 0.2, segment: int = 20000,
                   max_segments: int = 5) -> tuple[float, int]:
    """Sample entropy with an explicit tolerance, median over segments for long signals.

    Parameters
    ----------
    x : ndarray
        Signal.
    m : int
        Embedding dimension (antropy needs m >= 2).
    r_frac : float
        Tolerance as a fraction of each segment's standard deviation (ddof = 0).
    segment : int
        Segment length in samples; shorter signals are used whole.
    max_segments : int
        At most this many evenly spaced segments are evaluated.

    Returns
    -------
    se : float
        Median sample entropy; 0 for a constant segment, ``inf`` when no template matches.
    n_segments : int
        Segments used.
    """
    x = np.asarray(x, float)
    n_seg = max(1, len(x) // segment)
    starts = np.unique(np.linspace(0, n_seg - 1, min(n_seg, max_segments)).round().astype(int)) * segment
    seg_len = segment if n_seg > 1 else len(x)
    vals = []
    for s in starts:
        seg = x[s:s + seg_len]
        sd = seg.std()
        vals.append(0.0 if sd == 0 else sampen_kdtree(seg, m, r_frac * sd))
    return float(np.median(vals)), len(starts)


def imf_entropies(imfs: np.ndarray, **kw) -> np.ndarray:
    """Sample entropy of every row of ``imfs`` (keywords as :func:`sample_entropy`).

    Parameters
    ----------
    imfs : ndarray, shape (n_imfs, n)
        IMFs, highest frequency first.
    **kw
        Passed to :func:`sample_entropy`.

    Returns
    -------
    ndarray, shape (n_imfs,)
    """
    return np.array([sample_entropy(c, **kw)[0] for c in imfs])


def raw_classes(entropies: np.ndarray, noise_min: float = NOISE_SE_MIN,
                drift_max: float = DRIFT_SE_MAX) -> np.ndarray:
    """Per-IMF class from thresholds alone (may be non-monotone).

    Parameters
    ----------
    entropies : ndarray
        Sample entropy per IMF.
    noise_min, drift_max : float
        Noise if SE >= noise_min; drift if SE < drift_max; mixed otherwise.

    Returns
    -------
    ndarray of int
        :data:`NOISE`, :data:`MIXED` or :data:`DRIFT` per IMF.
    """
    e = np.asarray(entropies, float)
    return np.where(e >= noise_min, NOISE, np.where(e < drift_max, DRIFT, MIXED)).astype(int)


def monotone_classes(raw: np.ndarray) -> np.ndarray:
    """The non-decreasing class sequence closest (L1) to ``raw``.

    Parameters
    ----------
    raw : ndarray of int
        Classes per IMF in IMF order.

    Returns
    -------
    ndarray of int
        ``[NOISE]*i + [MIXED]*(j-i) + [DRIFT]*(n-j)`` minimising sum |raw - out|;
        ties go to the split that keeps more IMFs mixed, then the earliest one.
    """
    raw = np.asarray(raw, int)
    n = len(raw)
    pre = [np.concatenate([[0], np.cumsum(np.abs(raw - c))]) for c in (NOISE, MIXED, DRIFT)]
    i, j = np.triu_indices(n + 1)  # all 0 <= i <= j <= n
    cost = pre[0][i] + (pre[1][j] - pre[1][i]) + (pre[2][n] - pre[2][j])
    order = np.lexsort((i, -(j - i), cost))  # least cost, then most mixed, then earliest
    k = order[0]
    return np.array([NOISE] * i[k] + [MIXED] * (j[k] - i[k]) + [DRIFT] * (n - j[k]), int)


def classify(entropies: np.ndarray, noise_min: float = NOISE_SE_MIN,
             drift_max: float = DRIFT_SE_MAX) -> np.ndarray:
    """Monotone noise / mixed / drift classes from sample entropies.

    Parameters
    ----------
    entropies : ndarray
        Sample entropy per IMF, highest-frequency IMF first.
    noise_min, drift_max : float
        Thresholds, see :func:`raw_classes`.

    Returns
    -------
    ndarray of int
        Non-decreasing classes (noise=0, mixed=1, drift=2).
    """
    return monotone_classes(raw_classes(entropies, noise_min, drift_max))


def calibrate_thresholds(entropies: list[np.ndarray], labels: list[np.ndarray],
                         grid: np.ndarray | None = None) -> tuple[float, float, float]:
    """Thresholds that best reproduce labelled classes after the monotone projection.

    Parameters
    ----------
    entropies : list of ndarray
        Sample entropies per IMF, one array per labelled decomposition.
    labels : list of ndarray
        True class per IMF (same shapes).
    grid : ndarray, optional
        Candidate threshold values (default 89 log-spaced values 1e-4 ... 2.5: IMF entropies span decades).

    Returns
    -------
    noise_min, drift_max : float
        The thresholds with the highest accuracy (ties: the midpoint of the best run of
        noise_min values for the best drift_max, so the choice is not at an edge).
    accuracy : float
        Fraction of IMFs classified as labelled.
    """
    grid = np.round(np.geomspace(1e-4, 2.5, 89), 6) if grid is None else np.asarray(grid)
    total = sum(len(lab) for lab in labels)
    acc = np.full((len(grid), len(grid)), -1.0)
    for a, nm in enumerate(grid):
        for b, dm in enumerate(grid):
            if dm <= nm:
                hits = sum(int((classify(e, nm, dm) == lab).sum()) for e, lab in zip(entropies, labels))
                acc[a, b] = hits / total
    best = acc.max()
    a_idx, b_idx = np.nonzero(acc == best)
    b = int(np.median(b_idx))
    rows = a_idx[b_idx == b] if np.any(b_idx == b) else a_idx
    a = int(rows[len(rows) // 2])
    return float(grid[a]), float(grid[b]), float(best)
