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
from .segments import segment_bounds

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


def white_noise_floor_dps(record: Record, column: str = "rate_dps") -> float:
    """Per-sample white-noise SD of a record, from successive differences inside each stretch between gaps.

    ``sqrt(mean(diff^2) / 2)`` removes anything slow (drift, a bias, a temperature law), so it
    is the RMS a perfect drift model would leave on a static record; on a record of bursts it is
    the white noise within the bursts.

    Parameters
    ----------
    record : Record
    column : str
        Channel (the true rate is subtracted first when known).

    Returns
    -------
    float
        deg/s for ``rate_dps``.
    """
    y = np.asarray(record[column], dtype=float) - truth_of(record)[0]
    t = record.time_s
    d = []
    for a, b in segment_bounds(t):
        seg = np.diff(y[a:b])
        d.append(seg[np.isfinite(seg)])
    d = np.concatenate(d) if d else np.array([])
    return float(np.sqrt(np.mean(d * d) / 2.0)) if d.size else float("nan")


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
            rms[ref] = rms_dps(record, get_method(ref)().fit(train).transform(record))
    floor = white_noise_floor_dps(record)
    b = rms.get("bias")
    rel = {k: (v / b if b else None) for k, v in rms.items()}
    rel["white_noise_floor"] = floor / b if b else None
    best = min(rms, key=rms.get)
    ties = [k for k in REFERENCES if k != method and k in rms and abs(rms[k] - rms[method]) <= 1e-3 * rms[method]]
    if ties and rms[ties[0]] <= rms[method]:
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
