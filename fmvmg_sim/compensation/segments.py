"""Gaps, bursts and bins: the time structure a compensator must respect.

A measured record is often not one continuous stretch: a logger drops samples, a
thermal-vacuum test wakes the sensor for 5 s every 5 min. Here a record is cut into
*segments* at every gap (a time step longer than :data:`GAP_FACTOR` times the median step),
and everything the temperature models compute from it stays inside one segment:

* bins (1 s means by default) never straddle a gap;
* moving averages and derivatives use only the samples of their own segment (windows are
  shortened at segment edges, never filled across them);
* validation folds are cut at segment boundaries when the record is made of bursts
  (:mod:`.selection`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: A time step longer than this many median steps is a gap.
GAP_FACTOR = 1.5


def segment_bounds(t_s: np.ndarray, gap_factor: float = GAP_FACTOR) -> list[tuple[int, int]]:
    """Index ranges ``[start, stop)`` of the stretches between gaps.

    Parameters
    ----------
    t_s : ndarray
        Strictly increasing times in s.
    gap_factor : float
        A step longer than ``gap_factor`` times the median step starts a new segment.

    Returns
    -------
    list of (int, int)
    """
    t = np.asarray(t_s, dtype=float)
    if t.size < 2:
        return [(0, int(t.size))]
    dt = np.diff(t)
    cuts = np.flatnonzero(dt > gap_factor * np.median(dt)) + 1
    edges = np.concatenate(([0], cuts, [t.size]))
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


@dataclass
class Bins:
    """Bin means of a record's samples, never straddling a gap.

    Parameters
    ----------
    t_s : ndarray
        Mean time of each bin.
    counts : ndarray
        Samples per bin (the weight of the bin in a fit).
    segment : ndarray
        Segment number of each bin.
    sample_bin : ndarray
        Bin number of every sample.
    width_s : float
        Nominal bin width.
    """

    t_s: np.ndarray
    counts: np.ndarray
    segment: np.ndarray
    sample_bin: np.ndarray
    width_s: float

    def __len__(self) -> int:
        return len(self.t_s)

    def mean(self, x: np.ndarray) -> np.ndarray:
        """Bin means of a per-sample series.

        Parameters
        ----------
        x : ndarray
            One value per sample.

        Returns
        -------
        ndarray
            One value per bin.
        """
        return np.bincount(self.sample_bin, weights=np.asarray(x, dtype=float), minlength=len(self)) / self.counts

    def segments(self) -> list[slice]:
        """Slices of the bins of each segment, in time order.

        Returns
        -------
        list of slice
        """
        edges = np.concatenate(([0], np.flatnonzero(np.diff(self.segment)) + 1, [len(self)]))
        return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]

    def to_samples(self, t_s: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Per-bin values interpolated linearly in time back to the samples, inside each segment.

        Parameters
        ----------
        t_s : ndarray
            The samples' times (the record the bins were made from).
        values : ndarray
            One value per bin.

        Returns
        -------
        ndarray
            One value per sample; a segment with one bin takes that bin's value.
        """
        out = np.empty(len(t_s))
        seg_of_sample = self.segment[self.sample_bin]  # non-decreasing: samples are in time order
        for s in self.segments():
            k = self.segment[s.start]
            a, b = np.searchsorted(seg_of_sample, [k, k + 1])
            out[a:b] = np.interp(t_s[a:b], self.t_s[s], values[s])
        return out


def make_bins(t_s: np.ndarray, width_s: float = 1.0, gap_factor: float = GAP_FACTOR) -> Bins:
    """Bins of ``width_s`` seconds inside each segment of ``t_s``.

    Parameters
    ----------
    t_s : ndarray
        Strictly increasing times in s.
    width_s : float
        Bin width.
    gap_factor : float
        Gap definition (:func:`segment_bounds`).

    Returns
    -------
    Bins
    """
    t = np.asarray(t_s, dtype=float)
    sample_bin = np.empty(t.size, dtype=np.int64)
    seg_of_bin = []
    n = 0
    for k, (a, b) in enumerate(segment_bounds(t, gap_factor)):
        local = np.floor((t[a:b] - t[a]) / width_s).astype(np.int64)
        _, inv = np.unique(local, return_inverse=True)
        sample_bin[a:b] = inv + n
        nb = int(inv.max()) + 1 if b > a else 0
        seg_of_bin += [k] * nb
        n += nb
    counts = np.bincount(sample_bin, minlength=n).astype(float)
    tb = np.bincount(sample_bin, weights=t, minlength=n) / counts
    return Bins(tb, counts, np.asarray(seg_of_bin, dtype=np.int64), sample_bin, float(width_s))


def _window_sums(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    c = np.concatenate(([0.0], np.cumsum(x)))
    return c[hi] - c[lo]


def _windows(tb: np.ndarray, span_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Index ranges [lo, hi) of the bins within +- span/2 of each bin (inside one segment)."""
    half = 0.5 * span_s
    return np.searchsorted(tb, tb - half, "left"), np.searchsorted(tb, tb + half, "right")


def smooth_within(bins: Bins, xb: np.ndarray, span_s: float) -> np.ndarray:
    """Centred moving average of bin values over ``span_s`` seconds, inside each segment.

    Parameters
    ----------
    bins : Bins
        The bins ``xb`` belongs to.
    xb : ndarray
        One value per bin.
    span_s : float
        Window width; 0 or less returns ``xb`` unchanged. Windows shrink at segment edges.

    Returns
    -------
    ndarray
    """
    xb = np.asarray(xb, dtype=float)
    if span_s <= 0:
        return xb.copy()
    out = np.empty_like(xb)
    for s in bins.segments():
        t, x, w = bins.t_s[s], xb[s], bins.counts[s]
        lo, hi = _windows(t, span_s)
        out[s] = _window_sums(w * x, lo, hi) / _window_sums(w, lo, hi)
    return out


def slope_within(bins: Bins, xb: np.ndarray, span_s: float) -> np.ndarray:
    """Local least-squares slope d(x)/dt per s over a centred window of ``span_s``, inside each segment.

    A window is shortened where it meets a segment edge; a segment of one bin has slope 0.

    Parameters
    ----------
    bins : Bins
    xb : ndarray
        One value per bin.
    span_s : float
        Window width in s.

    Returns
    -------
    ndarray
        Slope per bin, units of ``xb`` per second.
    """
    xb = np.asarray(xb, dtype=float)
    out = np.zeros_like(xb)
    for s in bins.segments():
        t, x, w = bins.t_s[s], xb[s], bins.counts[s]
        if len(t) < 2:
            continue
        tc = t - t.mean()
        lo, hi = _windows(t, max(span_s, 2.0 * bins.width_s))
        sw, st, sx = _window_sums(w, lo, hi), _window_sums(w * tc, lo, hi), _window_sums(w * x, lo, hi)
        stt, stx = _window_sums(w * tc * tc, lo, hi), _window_sums(w * tc * x, lo, hi)
        den = sw * stt - st * st
        ok = den > 1e-12 * np.maximum(sw * stt, 1e-300)
        out[s] = np.where(ok, (sw * stx - st * sx) / np.where(ok, den, 1.0), 0.0)
    return out


def describe(t_s: np.ndarray, gap_factor: float = GAP_FACTOR) -> dict:
    """How the record is sampled: segments, gaps and whether it is a record of bursts.

    Parameters
    ----------
    t_s : ndarray
        Times in s.
    gap_factor : float
        Gap definition (:func:`segment_bounds`).

    Returns
    -------
    dict
        ``segments``, ``gaps``, ``sample_interval_s``, ``longest_segment_s``,
        ``median_segment_s``, ``longest_gap_s``, ``median_gap_s`` and ``bursty`` (at least
        three segments, and the typical segment shorter than the typical gap).
    """
    t = np.asarray(t_s, dtype=float)
    seg = segment_bounds(t, gap_factor)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    durations = np.array([t[b - 1] - t[a] + dt for a, b in seg])
    gaps = np.array([t[b] - t[b - 1] for _, b in seg[:-1]])
    return {"segments": len(seg), "gaps": len(gaps), "sample_interval_s": dt,
            "longest_segment_s": float(durations.max()), "median_segment_s": float(np.median(durations)),
            "longest_gap_s": float(gaps.max()) if gaps.size else 0.0,
            "median_gap_s": float(np.median(gaps)) if gaps.size else 0.0,
            "bursty": bool(len(seg) >= 3 and gaps.size and np.median(durations) < np.median(gaps))}
