"""Empirical mode decomposition of a record channel (paper 000 section 3.1).

Backed by the ``emd`` package (``emd.sift.sift``, classic sift, library defaults:
SD stopping 0.1, energy threshold 50 dB, spline envelopes). It was chosen over PyEMD by
measurement on this machine (gyro-like noise + drift, fs = 100 Hz, median of 3 runs;
``python benchmarks/compensation.py --emd-choice`` repeats it):

=========  ==============  ==============  ===============  ===============
N          PyEMD 1.10.0    emd 0.8.1       IMFs PyEMD/emd   peak RSS emd
=========  ==============  ==============  ===============  ===============
1e4        0.215 s         0.034 s         12 / 8           110 MB
1e5        5.37 s          0.276 s         16 / 8           136 MB
1e6        604 s (ref.)    3.73 s          23 / 9           336 MB
4.68e6     --              42.8 s          -- / 16          1.39 GB
=========  ==============  ==============  ===============  ===============

The two libraries use different stopping rules, so IMF counts (and the sample
entropy thresholds calibrated on them) belong to ``emd`` with these settings.
``emd`` is GPL-2.0-or-later (see the note in pyproject.toml).
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

#: Fewest samples the decomposition accepts (a few dozen extrema are needed for a sift).
MIN_EMD_SAMPLES = 256


@dataclass
class EMDResult:
    """IMFs and residue of one decomposition.

    Parameters
    ----------
    imfs : ndarray, shape (n_imfs, n)
        Intrinsic mode functions, highest frequency first (residue excluded).
    residue : ndarray, shape (n,)
        The monotone-ish remainder; ``imfs.sum(0) + residue`` is the input.
    fs_Hz : float
        Sampling rate of the decomposed signal (after any decimation).
    decimation : int
        Block-average factor applied before the sift (1 = none).
    notes : list of str
        What was done to the data (decimation), for reports.
    """

    imfs: np.ndarray
    residue: np.ndarray
    fs_Hz: float
    decimation: int = 1
    notes: list[str] = field(default_factory=list)

    @property
    def n_imfs(self) -> int:
        """Number of IMFs (residue excluded)."""
        return int(self.imfs.shape[0])

    def mean_periods_s(self) -> np.ndarray:
        """Mean period of each IMF in s, from its zero-crossing count."""
        return np.array([mean_period_s(c, self.fs_Hz) for c in self.imfs])


def mean_period_s(x: np.ndarray, fs_Hz: float) -> float:
    """Mean period of an oscillation in s: 2 x duration / number of zero crossings.

    Parameters
    ----------
    x : ndarray
        An IMF.
    fs_Hz : float
        Sampling rate.

    Returns
    -------
    float
        Mean period (``inf`` when there are fewer than two crossings).
    """
    s = np.signbit(x - np.mean(x))
    n_cross = int(np.count_nonzero(s[1:] != s[:-1]))
    return 2.0 * len(x) / fs_Hz / n_cross if n_cross >= 2 else float("inf")


def block_average(x: np.ndarray, q: int) -> np.ndarray:
    """Mean over consecutive blocks of ``q`` samples (the last partial block included).

    Parameters
    ----------
    x : ndarray
        Signal.
    q : int
        Block length.

    Returns
    -------
    ndarray
        ``ceil(len(x)/q)`` block means.
    """
    n = len(x)
    full = n // q
    out = x[: full * q].reshape(full, q).mean(axis=1)
    return np.append(out, x[full * q:].mean()) if n % q else out


def emd_decompose(x: np.ndarray, fs_Hz: float, max_imfs: int | None = None,
                  decimate_to_Hz: float | None = None, name: str = "signal") -> EMDResult:
    """Decompose ``x`` into IMFs and a residue.

    Parameters
    ----------
    x : ndarray
        Uniformly sampled, finite signal.
    fs_Hz : float
        Its sampling rate.
    max_imfs : int, optional
        Stop after this many IMFs (the rest goes to the residue).
    decimate_to_Hz : float, optional
        Block-average to about this rate first (only for signals with nothing to keep
        above it, such as a temperature trend); recorded in ``notes``.
    name : str
        Channel name for error messages and notes.

    Returns
    -------
    EMDResult

    Raises
    ------
    InputError
        Non-finite samples, or fewer than :data:`MIN_EMD_SAMPLES` samples to decompose.
    """
    x = np.asarray(x, float)
    if not np.all(np.isfinite(x)):
        raise InputError(f"{name} has NaN or infinite samples; EMD needs a complete signal")
    q, notes = 1, []
    if decimate_to_Hz is not None and fs_Hz > decimate_to_Hz:
        q = max(1, int(np.floor(fs_Hz / decimate_to_Hz + 1e-6)))
        if len(x) // q < MIN_EMD_SAMPLES:  # too short to decimate that far
            q = max(1, len(x) // MIN_EMD_SAMPLES)
        if q > 1:
            x = block_average(x, q)
            notes.append(f"{name} block-averaged by {q} to {fs_Hz / q:g} Hz before EMD")
    if len(x) < MIN_EMD_SAMPLES:
        raise InputError(f"{name} has {len(x)} samples; EMD needs at least {MIN_EMD_SAMPLES}")
    import emd as _emd  # lazy: GPL-2+ library, imported only when a decomposition is run

    logging.getLogger("emd").setLevel(logging.WARNING)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # emd 0.8.1's np.log10(where=) warning
        try:
            out = _emd.sift.sift(x, max_imfs=max_imfs, verbose="WARNING", return_residual=True)
        except UnboundLocalError:  # emd 0.8.1 fails instead of returning no IMF (monotone input)
            out = x[:, None]
    out = np.ascontiguousarray(out.T)
    if out.shape[0] == 1:  # nothing oscillates: all residue
        return EMDResult(np.zeros((0, len(x))), out[0], fs_Hz / q, q, notes)
    return EMDResult(out[:-1], out[-1], fs_Hz / q, q, notes)


def trend(t_s: np.ndarray, x: np.ndarray, fs_Hz: float, min_period_s: float = 300.0,
          decimate_to_Hz: float = 1.0, name: str = "temperature_C") -> tuple[np.ndarray, dict]:
    """Trend of a slow channel: EMD residue plus IMFs whose mean period exceeds ``min_period_s``.

    Parameters
    ----------
    t_s : ndarray
        Uniform time base of ``x``.
    x : ndarray
        The channel (e.g. the temperature sensor reading).
    fs_Hz : float
        Sampling rate.
    min_period_s : float
        IMFs with a longer mean period belong to the trend (compensation.md: 300 s).
    decimate_to_Hz : float
        Decimate (block average) to this rate before the sift.
    name : str
        Channel name for messages.

    Returns
    -------
    trend : ndarray
        The trend on the original time base (linear interpolation from the decimated grid).
    info : dict
        ``n_imfs``, ``n_trend_imfs``, ``decimation`` and ``notes``.
    """
    res = emd_decompose(x, fs_Hz, decimate_to_Hz=decimate_to_Hz, name=name)
    keep = res.mean_periods_s() > min_period_s
    tr = res.residue + res.imfs[keep].sum(axis=0)
    if res.decimation > 1:
        q = res.decimation
        tc = block_average(np.asarray(t_s, float), q)
        tr = np.interp(t_s, tc, tr)
    info = {"n_imfs": res.n_imfs, "n_trend_imfs": int(keep.sum()), "decimation": res.decimation,
            "notes": res.notes}
    return tr, info
