"""A uniform, gap-free sample series from one channel of a record.

Rules (stated here once; ``fmvmg allan`` and any analysis that needs even sampling use them):

1. The nominal step h is the median of ``diff(time_s)``. For a series that passes rule 2 the
   sample rate is fs = (n - 1) / (t_last - t_first) (the mean step, more precise than the median
   of rounded time stamps); after resampling fs = 1 / h. fs is rounded to 10 significant digits.
2. Without ``resample``, every step must lie within ``STEP_TOL`` (1 %) of h. The first step that
   does not is refused with :class:`InputError` naming the file line of the later sample.
3. Missing samples (empty cell / ``nan``) at the start or end are trimmed. Inside the series,
   runs of at most ``MAX_NAN_FILL`` (3) consecutive missing samples are filled by linear
   interpolation between their neighbours; a longer run is refused, naming its first line.
4. With ``resample``, missing samples are dropped and the remaining samples are linearly
   interpolated onto the uniform grid t0 + k h; a gap (a step between kept samples) longer
   than ``MAX_GAP_STEPS`` (10) times h is refused, naming the line after it.

Every fill or resampling is recorded in :attr:`Series.notes`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..record import KNOWN_COLUMNS, Record, data_line_number

#: Relative tolerance of a time step around the median step.
STEP_TOL = 0.01
#: Longest run of missing samples filled by interpolation without ``resample``.
MAX_NAN_FILL = 3
#: Longest gap, in median steps, that ``resample`` bridges.
MAX_GAP_STEPS = 10

_SUFFIX_UNITS = {"dps": "deg/s", "V": "V", "C": "degC", "Hz": "Hz", "s": "s", "g": "g", "rad_s": "rad/s"}


def column_unit(name: str) -> str:
    """Unit of a record column: the contract's unit, else one read from the name's suffix.

    Parameters
    ----------
    name : str
        Column name such as ``rate_dps`` or ``quadrature_V``.

    Returns
    -------
    str
        The unit (``"deg/s"``, ``"V"``, ...), or ``""`` when unknown.
    """
    if name in KNOWN_COLUMNS:
        return KNOWN_COLUMNS[name][0]
    for suffix, unit in _SUFFIX_UNITS.items():
        if name.endswith("_" + suffix):
            return unit
    return ""


@dataclass
class Series:
    """Evenly sampled values of one channel, ready for :func:`~fmvmg_sim.analysis.allan.allan_deviation`.

    Parameters
    ----------
    values : ndarray
        Finite samples on a uniform grid.
    fs_Hz : float
        Sample rate (1 / median step).
    t0_s : float
        Time of the first sample.
    column : str
        The channel's name.
    unit : str
        The channel's unit.
    resampled : bool
        True when the values were interpolated onto a new grid.
    n_filled : int
        Samples produced by interpolation (missing samples or gap bridging).
    notes : list of str
        What was done to the data, for the user.
    """

    values: np.ndarray
    fs_Hz: float
    t0_s: float
    column: str
    unit: str
    resampled: bool = False
    n_filled: int = 0
    notes: list[str] = field(default_factory=list)


def _where(record: Record, row: int) -> str:
    line = data_line_number(record.path, row) if record.path else None
    if line is None:
        return f"{record.path or 'record'} row {row}"
    return f"{record.path} line {line}"


def series_from_record(record: Record, column: str = "rate_dps", resample: bool = False, *,
                       step_tol: float = STEP_TOL, max_nan_fill: int = MAX_NAN_FILL,
                       max_gap_steps: int = MAX_GAP_STEPS) -> Series:
    """Evenly sampled series of ``column`` under the module's rules.

    Parameters
    ----------
    record : Record
        A record read by :func:`fmvmg_sim.record.read_record` (``time_s`` strictly increasing).
    column : str, optional
        Channel to extract.
    resample : bool, optional
        Interpolate onto a uniform grid at the median step instead of refusing uneven steps.
    step_tol : float, optional
        Relative tolerance of a step around the median step.
    max_nan_fill : int, optional
        Longest run of missing samples filled without ``resample``.
    max_gap_steps : int, optional
        Longest gap (in median steps) bridged with ``resample``.

    Returns
    -------
    Series
        Finite samples on a uniform grid, the sample rate and notes on what was filled.

    Raises
    ------
    InputError
        Missing column, fewer than 2 finite samples, uneven steps (without ``resample``), a run
        of missing samples or a gap over the limit; the message names the file line.
    """
    if column not in record:
        raise InputError(f"no column {column!r}; columns are {sorted(record.columns)}", record.path)
    t = record.time_s
    y = np.array(record[column], dtype=float)
    finite = np.isfinite(y)
    if finite.sum() < 2:
        raise InputError(f"column {column!r} has fewer than 2 finite samples", record.path)
    unit = column_unit(column)
    notes: list[str] = []
    dt_all = np.diff(t)
    h = float(np.median(dt_all))
    i0, i1 = int(np.argmax(finite)), int(len(y) - np.argmax(finite[::-1]) - 1)
    if i0 > 0 or i1 < len(y) - 1:
        notes.append(f"{column}: trimmed {i0} leading and {len(y) - 1 - i1} trailing missing samples")
    t, y, finite = t[i0:i1 + 1], y[i0:i1 + 1], finite[i0:i1 + 1]

    if not resample:
        dt = np.diff(t)
        bad = np.flatnonzero(np.abs(dt / h - 1.0) > step_tol)
        if bad.size:
            k = int(bad[0]) + 1
            raise InputError(
                f"time_s step {dt[k - 1]:.6g} s before this line differs from the median step {h:.6g} s "
                f"by more than {100 * step_tol:g} % (a gap or uneven sampling); use --resample to interpolate "
                f"onto a uniform grid (bridges gaps up to {max_gap_steps} steps)", _where(record, i0 + k))
        n_fill = 0
        if not finite.all():
            idx = np.arange(len(y))
            for a, b in _nan_runs(finite):
                if b - a > max_nan_fill:
                    raise InputError(
                        f"{b - a} missing {column} samples in a row from this line; at most {max_nan_fill} are "
                        f"interpolated (use --resample to bridge up to {max_gap_steps - 1})", _where(record, i0 + a))
            n_fill = int((~finite).sum())
            y[~finite] = np.interp(idx[~finite], idx[finite], y[finite])
            notes.append(f"{column}: {n_fill} missing sample(s) filled by linear interpolation "
                         f"(runs of at most {max_nan_fill})")
        fs = _round_sig((len(t) - 1) / (t[-1] - t[0]))
        return Series(y, fs, float(t[0]), column, unit, False, n_fill, notes)

    rows = i0 + np.flatnonzero(finite)
    tt, yy = t[finite], y[finite]
    dtt = np.diff(tt)
    big = np.flatnonzero(dtt > max_gap_steps * h * (1.0 + step_tol))
    if big.size:
        k = int(big[0])
        raise InputError(
            f"gap of {dtt[k]:.6g} s ({dtt[k] / h:.1f} median steps of {h:.6g} s) before this line exceeds the "
            f"--resample limit of {max_gap_steps} steps", _where(record, int(rows[k + 1])))
    n_grid = int(np.floor((tt[-1] - tt[0]) / h * (1.0 + 1e-12) + 1e-9)) + 1
    grid = tt[0] + np.arange(n_grid) * h
    values = np.interp(grid, tt, yy)
    n_gaps = int((dtt > h * (1.0 + step_tol)).sum())
    n_fill = max(0, n_grid - len(tt))
    notes.append(f"{column}: resampled onto a uniform {h:.6g} s grid by linear interpolation "
                 f"({n_gaps} gap(s) bridged, {len(tt)} samples -> {n_grid})")
    return Series(values, _round_sig(1.0 / h), float(tt[0]), column, unit, True, n_fill, notes)


def _round_sig(x: float, digits: int = 10) -> float:
    return float(f"{x:.{digits}g}")


def _nan_runs(finite: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [start, stop) of the runs of missing samples."""
    edges = np.diff(np.concatenate(([0], (~finite).astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))
