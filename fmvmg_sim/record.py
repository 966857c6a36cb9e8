"""The record format (docs/formats.md section 2): read, validate and write.

A record is a CSV file with optional ``# key: value`` metadata lines, one header
row of unit-suffixed column names and numeric rows. ``time_s`` must be strictly
increasing (uneven steps, i.e. gaps, are allowed); empty cells and ``nan`` mark
missing samples. Unknown columns are kept and reported with a warning.

Reading never raises anything but :class:`fmvmg_sim.errors.InputError` for a bad
file, and names the line. Writing is atomic: a temporary file in the target
folder is renamed over the destination, so a record is written whole or not at all.
"""

from __future__ import annotations

import gzip
import io
import math
import os
import tempfile
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError

#: Columns the contract defines, with their unit and whether they are required.
KNOWN_COLUMNS: dict[str, tuple[str, bool]] = {
    "time_s": ("s", True),
    "temperature_C": ("degC", True),
    "rate_dps": ("deg/s", True),
    "rate_V": ("V", False),
    "rate_true_dps": ("deg/s", False),
    "quadrature_V": ("V", False),
    "drive_amplitude_V": ("V", False),
    "agc_effort_V": ("V", False),
    "drive_frequency_Hz": ("Hz", False),
    "rate_raw_dps": ("deg/s", False),  # written by `fmvmg compensate` (docs/formats.md section 3)
}
REQUIRED_COLUMNS = tuple(k for k, (_, req) in KNOWN_COLUMNS.items() if req)
#: Column order used when writing a simulated record.
RECORD_ORDER = (
    "time_s", "temperature_C", "rate_dps", "rate_V", "rate_true_dps", "quadrature_V",
    "drive_amplitude_V", "agc_effort_V", "drive_frequency_Hz",
)


class RecordWarning(UserWarning):
    """A recoverable oddity in a record (unknown column, missing samples)."""


@dataclass
class Record:
    """Named channels on one time base, plus ``# key: value`` metadata.

    Parameters
    ----------
    columns : dict of str to ndarray
        Channels by contract name (``time_s``, ``rate_dps``, ...), all the same length.
    metadata : dict of str to str, optional
        Header metadata such as ``device`` or ``source``.
    path : str, optional
        The file the record was read from, for error messages.
    """

    columns: dict[str, np.ndarray]
    metadata: dict[str, str] = field(default_factory=dict)
    path: str | None = None

    def __post_init__(self) -> None:
        lengths = {len(np.asarray(v)) for v in self.columns.values()}
        if len(lengths) > 1:
            raise ValueError(f"record columns differ in length: {sorted(lengths)}")
        self.columns = {k: np.asarray(v, dtype=float) for k, v in self.columns.items()}

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def __len__(self) -> int:
        return len(self.columns["time_s"]) if "time_s" in self.columns else 0

    @property
    def time_s(self) -> np.ndarray:
        """The time base in seconds."""
        return self.columns["time_s"]

    def has(self, name: str) -> bool:
        """True when ``name`` is present and holds at least one finite sample."""
        return name in self.columns and bool(np.isfinite(self.columns[name]).any())

    def sample_interval_s(self) -> float:
        """Median time step in seconds (the nominal sampling interval)."""
        return float(np.median(np.diff(self.time_s)))

    def slice(self, mask_or_slice) -> "Record":
        """A new record holding the selected rows."""
        return Record({k: v[mask_or_slice] for k, v in self.columns.items()}, dict(self.metadata), self.path)


def _parse_float(cell: str) -> float:
    cell = cell.strip()
    if cell == "" or cell.lower() in ("nan", "na", "null"):
        return math.nan
    return float(cell)


def _read_text(p: Path) -> str:
    """The text of a record file, gunzipped when it starts with the gzip magic bytes (a ``.csv.gz``).

    A byte-order mark, as spreadsheet programs write, is dropped."""
    raw = p.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        raw = gzip.decompress(raw)
    return raw.decode("utf-8-sig")


def read_record(path: str | os.PathLike, required: tuple[str, ...] = REQUIRED_COLUMNS,
                warn_unknown: bool = True) -> Record:
    """Read and validate a record file.

    Parameters
    ----------
    path : path-like
        CSV file in the record format, or the same gzipped (``.csv.gz``).
    required : tuple of str, optional
        Columns that must be present (default: those the contract requires).
    warn_unknown : bool, optional
        Emit a :class:`RecordWarning` for columns the contract does not define.

    Returns
    -------
    Record

    Raises
    ------
    InputError
        Missing file, missing header or required column, a non-numeric cell, or a
        ``time_s`` that is missing or not strictly increasing; the message names the line.
    """
    p = Path(path)
    name = str(path)
    if p.is_dir():
        raise InputError("is a folder; expected a record file (CSV)", name)
    if not p.is_file():
        raise InputError("file not found", name)
    try:
        text = _read_text(p)
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text ({exc.reason} at byte {exc.start})", name) from None
    except (OSError, EOFError, zlib.error) as exc:
        raise InputError(f"not a readable gzip file ({exc})", name) from None
    lines = text.splitlines()
    metadata: dict[str, str] = {}
    header_idx = None
    for i, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s[1:].strip()
            if ":" in body:
                k, v = body.split(":", 1)
                metadata[k.strip()] = v.strip()
            continue
        header_idx = i
        break
    if header_idx is None:
        raise InputError("no header row (expected e.g. 'time_s,temperature_C,rate_dps')", name)
    header = [h.strip() for h in lines[header_idx].split(",")]
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise InputError(f"duplicate column(s) {dup} in the header", f"{name} line {header_idx + 1}")
    missing = [c for c in required if c not in header]
    if missing:
        raise InputError(f"missing required column(s) {missing}; header has {header}",
                         f"{name} line {header_idx + 1}")
    unknown = [h for h in header if h not in KNOWN_COLUMNS]
    if unknown and warn_unknown:
        warnings.warn(f"{name}: unknown column(s) {unknown} kept and ignored", RecordWarning, stacklevel=2)
    ncol = len(header)
    body_lines = lines[header_idx + 1:]
    data = None
    try:  # fast path: numpy's C parser on clean numeric data
        with warnings.catch_warnings():  # an empty body is named below, not in numpy's words
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(io.StringIO("\n".join(body_lines)), delimiter=",", ndmin=2,
                              dtype=float, comments="#")
        if data.size and data.shape[1] != ncol:
            data = None
    except ValueError:
        data = None
    if data is None:  # slow path: find and name the first bad line, accept empty cells
        rows = []
        for j, line in enumerate(body_lines):
            lineno = header_idx + 2 + j
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            cells = s.split(",")
            if len(cells) != ncol:
                raise InputError(f"expected {ncol} comma-separated cells, found {len(cells)}",
                                 f"{name} line {lineno}")
            try:
                rows.append([_parse_float(c) for c in cells])
            except ValueError:
                bad = next(c for c in cells if _is_bad(c))
                raise InputError(f"cell {bad.strip()!r} is not a number", f"{name} line {lineno}") from None
        data = np.asarray(rows, dtype=float).reshape(-1, ncol)
    if data.shape[0] == 0:
        raise InputError("the record has a header but no data rows", name)
    cols = {h: data[:, k].copy() for k, h in enumerate(header)}
    if "time_s" in cols:
        t = cols["time_s"]
        bad_t = np.flatnonzero(~np.isfinite(t))
        if bad_t.size:
            raise InputError("time_s is empty or not finite", f"{name} line {_data_lineno(lines, header_idx, bad_t[0])}")
        dt = np.diff(t)
        nonmono = np.flatnonzero(dt <= 0)
        if nonmono.size:
            k = nonmono[0] + 1
            raise InputError(f"time_s is not strictly increasing ({t[k - 1]:.12g} then {t[k]:.12g})",
                             f"{name} line {_data_lineno(lines, header_idx, k)}")
    return Record(cols, metadata, name)


def _is_bad(cell: str) -> bool:
    try:
        _parse_float(cell)
        return False
    except ValueError:
        return True


def _data_lineno(lines: list[str], header_idx: int, row: int) -> int:
    """1-based file line number of data row ``row`` (skipping blank and comment lines)."""
    count = -1
    for j in range(header_idx + 1, len(lines)):
        s = lines[j].strip()
        if not s or s.startswith("#"):
            continue
        count += 1
        if count == row:
            return j + 1
    return len(lines)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all (temporary file, then rename).

    The file gets the permissions of any new file under the process umask (0644 under 022),
    not the temporary file's 0600.

    Parameters
    ----------
    path : path-like
        Destination file.
    text : str
        Its whole content (written as UTF-8 with ``\\n`` line ends).
    """
    from .output import file_mode
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
        os.chmod(tmp, file_mode())
        os.replace(tmp, p)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_record(path: str | os.PathLike, record: Record) -> None:
    """Write a record atomically in the contract's CSV format.

    Known columns come first in contract order, then any others in their own order.
    Values are written with 12 significant digits; missing samples as ``nan``.

    Parameters
    ----------
    path : path-like
        Destination file.
    record : Record
        The channels and metadata to write.
    """
    names = [c for c in RECORD_ORDER if c in record.columns]
    names += [c for c in record.columns if c not in names]
    buf = io.StringIO()
    for k, v in record.metadata.items():
        buf.write(f"# {k}: {v}\n")
    buf.write(",".join(names) + "\n")
    if len(record):
        arr = np.column_stack([record.columns[c] for c in names])
        np.savetxt(buf, arr, delimiter=",", fmt="%.12g")
    atomic_write_text(path, buf.getvalue())


def data_line_number(path: str | os.PathLike, row: int) -> int | None:
    """1-based file line number of data row ``row`` of the record file at ``path``.

    Data rows are counted as :func:`read_record` counts them: after the header,
    skipping blank and ``#`` comment lines. Meant for error messages, so the file
    is re-read only when a caller needs to name a line.

    Parameters
    ----------
    path : path-like
        The record file the row came from.
    row : int
        0-based index of the data row (the index into the record's arrays).

    Returns
    -------
    int or None
        The line number, or None when the file cannot be read or has no header.
    """
    try:
        lines = _read_text(Path(path)).splitlines()
    except (OSError, EOFError, UnicodeDecodeError, zlib.error):
        return None
    header_idx = next((i for i, s in enumerate(lines) if s.strip() and not s.strip().startswith("#")), None)
    if header_idx is None:
        return None
    return _data_lineno(lines, header_idx, int(row))
