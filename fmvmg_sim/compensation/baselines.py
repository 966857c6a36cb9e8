"""What every compensated output is compared with: a bias calibration, a line in T, the noise floor.

A drift compensator earns its place only if it beats what a user would try first: a constant
bias taken from the training record (``bias``), and a straight line in temperature (``line``).
Below both lies the record's own white-noise floor, the RMS a perfect drift model would
still leave. :func:`compare` measures all of them on the same held-out record and says which
one wins.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..record import Record
from .base import get_method
from .segments import make_bins

#: The references, in the order they are reported.
REFERENCES = ("bias", "line")


def truth_of(record: Record) -> tuple[np.ndarray, str]:
    """The true rate to score against, and how it is known.

    Parameters
    ----------
    record : Record

    Returns
    -------
    (ndarray, str)
        ``rate_true_dps`` where the record has it; zeros otherwise (a static record: the true
        rate is a constant, e.g. the Earth's rate, which a bias calibration absorbs).
    """
    if record.has("rate_true_dps"):
        return np.nan_to_num(record["rate_true_dps"]), "rate_true_dps"
    return np.zeros(len(record)), "none: a static record is assumed (its constant true rate is part of the bias)"


def rms_dps(record: Record, out: np.ndarray) -> float:
    """RMS of (output - true rate) over the finite samples, in deg/s.

    Parameters
    ----------
    record : Record
    out : ndarray
        Compensated rate.

    Returns
    -------
    float
    """
    e = np.asarray(out, dtype=float) - truth_of(record)[0]
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e * e))) if e.size else float("nan")


#: Window of the noise floor's local means, in s.
FLOOR_WINDOW_S = 5.0


def white_noise_floor_dps(record: Record, column: str = "rate_dps", window_s: float = FLOOR_WINDOW_S) -> float:
    """RMS of a record's deviations from its own 5 s means, inside each stretch between gaps.

    What a perfect drift model (one that follows the record on a 5 s scale) would still leave:
    the white noise, and any noise faster than the window. On a record of 5 s bursts it is the
    noise within the bursts. Each window's mean costs one degree of freedom, which is given back
    (``sum(dev^2) / (n - n_windows)``), so white noise of SD sigma gives sigma whatever the window.

    Parameters
    ----------
    record : Record
    column : str
        Channel (the true rate is subtracted first when known).
    window_s : float
        Width of the local means.

    Returns
    -------
    float
        deg/s for ``rate_dps``.
    """
    y = np.asarray(record[column], dtype=float) - truth_of(record)[0]
    ok = np.isfinite(y)
    bins = make_bins(record.time_s[ok], window_s)
    y = y[ok]
    dev = y - bins.mean(y)[bins.sample_bin]
    dof = len(y) - len(bins)
    return float(np.sqrt(np.sum(dev * dev) / dof)) if dof > 0 else float("nan")


def compare(method: str, out: np.ndarray, train: Record, record: Record) -> dict:
    """Held-out RMS of a method's output beside a bias calibration, a line in T and the noise floor.

    Parameters
    ----------
    method : str
        Name of the method that made ``out``.
    out : ndarray
        Its compensated output on ``record``.
    train : Record
        The record it was fitted on (the references are fitted on it too).
    record : Record
        The held-out record ``out`` belongs to.

    Returns
    -------
    dict
        ``truth``, ``rms_dps`` (per method and reference, and ``white_noise_floor``),
        ``relative_to_bias`` (each RMS over the bias calibration's), ``best`` (the lowest RMS
        among the method and the references) and ``verdict`` (one sentence; it says so when a
        reference beats the method).
    """
    rms = {method: rms_dps(record, out)}
    for ref in REFERENCES:
        if ref == method:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rms[ref] = rms_dps(record, get_method(ref)().fit(train).compensate_rate_dps(record))
    floor = white_noise_floor_dps(record)
    b = rms.get("bias")
    rel = {k: (v / b if b else None) for k, v in rms.items()}
    rel["white_noise_floor"] = floor / b if b else None
    best = min(rms, key=rms.get)
    ties = [k for k in REFERENCES if k != method and k in rms and abs(rms[k] - rms[method]) <= 1e-3 * rms[method]]
    if ties:
        name = {"line": "a line in T", "bias": "a plain bias calibration"}[ties[0]]
        verdict = (f"{method} does as well as {name} on this record (held-out RMS {rms[method]:.4g} deg/s): "
                   "it adds nothing to it here")
        best = ties[0]
    elif best == method:
        verdict = f"{method} has the lowest held-out RMS ({rms[method]:.4g} deg/s; " + ", ".join(
            f"{k} {v:.4g}" for k, v in rms.items() if k != method) + ")"
    else:
        name = {"line": "a line in T", "bias": "a plain bias calibration"}.get(best, best)
        verdict = (f"{name} beats {method} on this record: held-out RMS {rms[best]:.4g} vs "
                   f"{rms[method]:.4g} deg/s")
    return {"truth": truth_of(record)[1], "rms_dps": {**rms, "white_noise_floor": floor},
            "relative_to_bias": rel, "best": best, "verdict": verdict}
