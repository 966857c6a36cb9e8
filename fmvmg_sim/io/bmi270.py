"""Bosch BMI270 serial logs (PuTTY captures) to records.

Log format (``tests/data/real-bmi270/PROVENANCE.txt``): one sample per line,
``Temperature[C], Accel_X, Accel_Y, Accel_Z, Gyro_X, Gyro_Y, Gyro_Z``, logged at 50 Hz with no
time column; gyro in deg/s printed with 2 decimals (effective quantum 0.061 deg/s); accel printed
as g/4 (the author multiplies by 4). A PuTTY banner line (``=~=~=... PuTTY log ...``) opens the
file and a few lines are corrupted by the serial link (cut, merged or garbled).

Rules
-----
* Banner lines and a text header line are not samples and are skipped silently.
* A sample line has exactly 7 comma-separated plain decimal numbers with a temperature in
  -40..125 degC, |gyro| <= 2000 deg/s and |accel| <= 16 g; any other line is corrupted.
* Every line from the first good sample to the last is one sample slot at ``rate_Hz``, so
  ``time_s = k / rate_Hz`` keeps the logger's time base: a corrupted line inside the log becomes
  a row of missing values (``nan``), and corrupted lines before the first or after the last good
  sample (a cut first or last line) are dropped. Every skipped line is reported with its reason.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..record import Record

#: Gyro axis -> column index in the log.
AXES = {"x": 4, "y": 5, "z": 6}
#: The log's columns: name, scale to the record unit.
LOG_COLUMNS = ("temperature_C", "accel_x_g", "accel_y_g", "accel_z_g", "gyro_x_dps", "gyro_y_dps", "gyro_z_dps")
ACCEL_SCALE = 4.0
TEMP_RANGE_C = (-40.0, 125.0)
GYRO_MAX_DPS = 2000.0
ACCEL_MAX_G = 16.0
_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")


@dataclass
class SkippedLine:
    """A log line that was not taken as a sample.

    Parameters
    ----------
    line : int
        1-based line number in the log.
    reason : str
        Why it was skipped.
    text : str
        The line (truncated to 80 characters).
    """

    line: int
    reason: str
    text: str


@dataclass
class Bmi270Import:
    """The record made from a BMI270 log and what was skipped.

    Parameters
    ----------
    record : Record
        ``time_s``, ``temperature_C``, ``rate_dps`` (the chosen axis), the other gyro axes as
        ``gyro_<a>_dps`` and ``accel_<a>_g``.
    skipped : list of SkippedLine
        Corrupted lines (banner and header lines are not listed).
    n_missing : int
        Rows of missing values (corrupted lines inside the log).
    axis : str
        Gyro axis used for ``rate_dps``.
    rate_Hz : float
        Assumed sample rate.
    """

    record: Record
    skipped: list[SkippedLine] = field(default_factory=list)
    n_missing: int = 0
    axis: str = "z"
    rate_Hz: float = 50.0

    def summary(self) -> dict:
        """JSON-ready summary: sample counts, axis, rate and the skipped lines.

        Returns
        -------
        dict
            ``n_samples``, ``duration_s``, ``rate_Hz``, ``axis``, ``n_missing``, ``n_skipped``, ``skipped``.
        """
        return {
            "n_samples": len(self.record),
            "duration_s": len(self.record) / self.rate_Hz,
            "rate_Hz": self.rate_Hz,
            "axis": self.axis,
            "n_missing": self.n_missing,
            "n_skipped": len(self.skipped),
            "skipped": [{"line": s.line, "reason": s.reason, "text": s.text} for s in self.skipped],
        }


def _classify(cells: list[str]) -> tuple[list[float] | None, str | None]:
    """Values of a sample line, or None and the reason it is corrupted."""
    if len(cells) != 7:
        return None, f"{len(cells)} comma-separated cells, expected 7"
    for j, c in enumerate(cells):
        if not _NUMBER.match(c.strip()):
            return None, f"cell {j + 1} ({LOG_COLUMNS[j]}) {c.strip()!r} is not a number"
    v = [float(c) for c in cells]
    if not TEMP_RANGE_C[0] <= v[0] <= TEMP_RANGE_C[1]:
        return None, f"temperature {v[0]:g} C outside {TEMP_RANGE_C[0]:g}..{TEMP_RANGE_C[1]:g} C"
    if max(abs(x) for x in v[4:]) > GYRO_MAX_DPS:
        return None, f"gyro value beyond +-{GYRO_MAX_DPS:g} deg/s"
    if max(abs(x) * ACCEL_SCALE for x in v[1:4]) > ACCEL_MAX_G:
        return None, f"accel value beyond +-{ACCEL_MAX_G:g} g"
    return v, None


def _is_banner(s: str) -> bool:
    return s.startswith("=~=") or "PuTTY log" in s


def _is_header(s: str) -> bool:
    return "gyro" in s.lower() and "temp" in s.lower()


def read_bmi270_log(path: str | Path, axis: str = "z", rate_Hz: float = 50.0) -> Bmi270Import:
    """Convert a BMI270 PuTTY log into a record under the module's rules.

    Parameters
    ----------
    path : path-like
        The log file.
    axis : {"x", "y", "z"}, optional
        Gyro axis written as ``rate_dps`` (default z).
    rate_Hz : float, optional
        Logging rate that defines ``time_s`` (default 50 Hz, from the log's README).

    Returns
    -------
    Bmi270Import
        The record, the skipped lines and the count of missing rows.

    Raises
    ------
    InputError
        Missing file, unknown axis, non-positive rate, or no sample line at all.
    """
    name = str(path)
    if axis not in AXES:
        raise InputError(f"axis must be x, y or z, got {axis!r}")
    if not (math.isfinite(rate_Hz) and rate_Hz > 0):
        raise InputError(f"rate must be positive, got {rate_Hz!r} Hz")
    p = Path(path)
    if p.is_dir():
        raise InputError("is a folder; expected a BMI270 log file", name)
    if not p.is_file():
        raise InputError("file not found", name)
    text = p.read_bytes().decode("utf-8-sig", errors="replace")  # serial noise may hold stray bytes
    slots: list[tuple[int, list[float] | None, str | None, str]] = []
    for i, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or _is_banner(s) or _is_header(s):
            continue
        values, reason = _classify(s.split(","))
        slots.append((i, values, reason, s[:80]))
    good = [k for k, sl in enumerate(slots) if sl[1] is not None]
    if not good:
        raise InputError("no BMI270 sample line (7 numbers: temperature, accel x/y/z, gyro x/y/z)", name)
    first, last = good[0], good[-1]
    skipped = [SkippedLine(i, ("before the first good sample: " if k < first else
                               "after the last good sample: " if k > last else "") + reason, txt)
               for k, (i, v, reason, txt) in enumerate(slots) if v is None]
    body = slots[first:last + 1]
    data = np.full((len(body), 7), np.nan)
    for k, (_, v, _, _) in enumerate(body):
        if v is not None:
            data[k] = v
    data[:, 1:4] *= ACCEL_SCALE
    cols = {"time_s": np.arange(len(body)) / rate_Hz, "temperature_C": data[:, 0],
            "rate_dps": data[:, AXES[axis]]}
    for a, j in AXES.items():
        if a != axis:
            cols[f"gyro_{a}_dps"] = data[:, j]
    for a, j in zip("xyz", (1, 2, 3)):
        cols[f"accel_{a}_g"] = data[:, j]
    n_missing = sum(1 for _, v, _, _ in body if v is None)
    meta = {
        "device": "bmi270",
        "source": f"import-bmi270 of {p.name}",
        "sample_rate_Hz": f"{rate_Hz:g} (assumed; the log has no time column)",
        "rate_axis": f"gyro {axis} -> rate_dps",
        "accel_scale": f"log value x {ACCEL_SCALE:g} -> g",
        "missing_samples": str(n_missing),
        "skipped_lines": ",".join(str(s.line) for s in skipped) or "none",
    }
    return Bmi270Import(Record(cols, meta, name), skipped, n_missing, axis, float(rate_Hz))
