"""Every compensator on measured records, beside a bias calibration, a line in T and the noise floor.

A measured record is split in time: each method is fitted on the first half and applied to
the second, and the reverse. Records of the same sensor and axis logged at temperatures that
do not overlap (a cold and a hot soak) are also crossed: fitted on one, applied to the other,
where the model must extrapolate. The figure of merit is the held-out RMS of the compensated
rate (against ``rate_true_dps`` when known, else against zero: a static record, whose constant
true rate is part of the bias) divided by the RMS a plain bias calibration from the training
part leaves. Three references stand beside the methods:

* ``bias``: the training part's mean rate (the ratio's denominator, 1 by definition);
* ``line``: a straight line in T fitted on the training part, extrapolated as a line;
* ``floor``: the test part's deviations from its own 5 s means (inside each burst): the white
  noise a perfect drift model would still leave.

A method that cannot use a record (a record of bursts, too short, with missing samples for a
method that needs even sampling) is reported as refused, with the reason it gives.
"""

from __future__ import annotations

import gzip
import re
import shutil
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..compensation.base import get_method
from ..compensation.baselines import rms_dps, white_noise_floor_dps
from ..compensation.poly import complete_rows
from ..compensation.segments import describe
from ..errors import InputError
from ..io.bmi270 import read_bmi270_log
from ..record import Record, read_record

#: Methods of the comparison, in table order (the default method, poly-baseline, first).
METHODS = ("poly-baseline", "physics", "line", "emd-rbf", "emd-rbf-ga", "emd-rbf-ga-kf", "vmd-wflp-cssvr")
#: The default method of ``fmvmg compensate``.
DEFAULT_METHOD = "poly-baseline"
#: Folders of the shared data that hold no thermal gyro record.
NOT_THERMAL = {"allan-reference": "Allan-deviation reference data, not a gyro record",
               "independent-dev": "simulated by an independent generator (the diagnosis development set), "
                                  "not measured"}


@dataclass
class MeasuredRecord:
    """One measured gyro record (one axis) and where it came from.

    Parameters
    ----------
    name : str
        ``folder/file[axis]``.
    group : str
        Records of the same sensor and axis share a group (they may be crossed).
    record : Record
    """

    name: str
    group: str
    record: Record


def _read_gz_record(path: Path) -> Record:
    """A gzip-compressed record, read through a temporary plain copy."""
    with tempfile.TemporaryDirectory() as tmp:
        plain = Path(tmp) / path.name[:-3]
        with gzip.open(path, "rb") as src, open(plain, "wb") as dst:
            shutil.copyfileobj(src, dst)
        rec = read_record(plain)
    rec.path = str(path)
    return rec


def load_records(data_dir: str | Path, independent: bool = False) -> tuple[list[MeasuredRecord], dict]:
    """The measured thermal gyro records under a shared-data folder.

    Folders holding ``*.csv`` records are read as records; a ``*bmi270*`` folder holds Bosch
    BMI270 PuTTY logs, imported once per gyro axis. Rows with a missing rate or temperature are
    kept (the methods that handle gaps treat them as gaps).

    Parameters
    ----------
    data_dir : path-like
        E.g. ``../shared/data`` or ``tests/data``.
    independent : bool
        Also read ``independent-dev``: records of this device simulated by an independent
        generator (auxiliary channels, known true rate, its own temperature laws and effects).

    Returns
    -------
    (list of MeasuredRecord, dict)
        The records, and the folders skipped with the reason.
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise InputError("no such folder", str(root))
    out, skipped = [], {}
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        if folder.name == "independent-dev" and independent:
            for f in sorted(folder.glob("*.csv.gz")):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    rec = _read_gz_record(f)
                stem = f.name[:-len(".csv.gz")]
                out.append(MeasuredRecord(f"{folder.name}/{stem}", f"{folder.name}/{stem}", rec))
            continue
        if folder.name in NOT_THERMAL:
            skipped[folder.name] = NOT_THERMAL[folder.name]
            continue
        files = sorted(folder.glob("*.csv"))
        if "bmi270" in folder.name:
            for f in files:
                for axis in "xyz":
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        rec = read_bmi270_log(f, axis=axis).record
                    out.append(MeasuredRecord(f"{folder.name}/{f.stem}[{axis}]", f"{folder.name}[{axis}]", rec))
            continue
        n = 0
        for f in files:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    rec = read_record(f)
            except InputError as exc:
                skipped[f"{folder.name}/{f.name}"] = f"not a record: {exc}"
                continue
            if not (rec.has("temperature_C") and rec.has("rate_dps")):
                skipped[f"{folder.name}/{f.name}"] = "no temperature_C or rate_dps"
                continue
            axis = rec.metadata.get("axis", f.stem)
            out.append(MeasuredRecord(f"{folder.name}/{f.stem}", f"{folder.name}[{axis}]", rec))
            n += 1
        if not n and files:
            skipped.setdefault(folder.name, "no thermal gyro record")
    return out, skipped


def halves(rec: Record) -> tuple[Record, Record]:
    """First and second half of a record in time (the cut falls where it falls: in a gap for bursts).

    Parameters
    ----------
    rec : Record

    Returns
    -------
    (Record, Record)
    """
    t = rec.time_s
    mid = t[0] + 0.5 * (t[-1] - t[0])
    return rec.slice(t < mid), rec.slice(t >= mid)


@dataclass
class Case:
    """One train/test pair and every method's result on it.

    Parameters
    ----------
    record : str
    direction : str
        ``"1st half -> 2nd half"``, ``"2nd half -> 1st half"`` or ``"A -> B"`` across records.
    train, test : Record
    results : dict
        Per method: ``{"rms_dps", "ratio", "chosen", "extrapolation", "wall_s"}`` or ``{"refused": reason}``.
    references : dict
        ``bias_rms_dps``, ``floor_rms_dps``, ``floor_ratio``.
    """

    record: str
    direction: str
    train: Record = field(repr=False)
    test: Record = field(repr=False)
    results: dict = field(default_factory=dict)
    references: dict = field(default_factory=dict)

    def describe(self) -> dict:
        """Sampling and temperature ranges of the pair.

        Returns
        -------
        dict
        """
        def info(r):
            T = r["temperature_C"][np.isfinite(r["temperature_C"])]
            s = describe(r.time_s)
            return {"samples": len(r), "duration_s": float(r.time_s[-1] - r.time_s[0]),
                    "temperature_C": [float(T.min()), float(T.max())], "bursty": s["bursty"],
                    "segments": s["segments"]}
        return {"train": info(self.train), "test": info(self.test)}


def make_cases(records: list[MeasuredRecord]) -> list[Case]:
    """Both halves of every record, and crossings of records of one group with disjoint temperatures.

    Parameters
    ----------
    records : list of MeasuredRecord

    Returns
    -------
    list of Case
    """
    cases = []
    for m in records:
        a, b = halves(m.record)
        cases += [Case(m.name, "1st half -> 2nd half", a, b), Case(m.name, "2nd half -> 1st half", b, a)]
    for i, m in enumerate(records):
        for n in records[i + 1:]:
            if m.group != n.group:
                continue
            Tm, Tn = (np.nanpercentile(r.record["temperature_C"], [1, 99]) for r in (m, n))
            if Tm[1] < Tn[0] or Tn[1] < Tm[0]:
                cases += [Case(m.group, f"{_short(m)} -> {_short(n)}", m.record, n.record),
                          Case(m.group, f"{_short(n)} -> {_short(m)}", n.record, m.record)]
    return cases


def _short(m: MeasuredRecord) -> str:
    return m.name.rsplit("/", 1)[-1].split("[")[0]


def evaluate_case(case: Case, methods=METHODS, method_params: dict | None = None) -> Case:
    """Fit every method on the case's training part and score it on its test part.

    Parameters
    ----------
    case : Case
    methods : sequence of str
    method_params : dict, optional
        Constructor arguments by method name.

    Returns
    -------
    Case
        ``case``, with ``results`` and ``references`` filled.
    """
    test_ok, _, _ = complete_rows(case.test)
    bias = get_method("bias")().fit(case.train)
    b = rms_dps(case.test, bias.compensate_rate_dps(case.test))
    floor = white_noise_floor_dps(test_ok)
    case.references = {"bias_rms_dps": b, "floor_rms_dps": floor, "floor_ratio": floor / b}
    for m in methods:
        kw = dict((method_params or {}).get(m, {}))
        cls = get_method(m)
        if "progress" in cls().get_params():
            kw.setdefault("progress", False)
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                comp = cls(**kw).fit(case.train)
                out = comp.compensate_rate_dps(case.test)
        except InputError as exc:
            case.results[m] = {"refused": exc.message}
            continue
        r = rms_dps(case.test, out)
        td = getattr(comp, "transform_diagnostics_", None) or {}
        ex = td.get("extrapolation") or {}
        sel = comp.selection_report()
        case.results[m] = {"rms_dps": r, "ratio": r / b, "chosen": sel["chosen"] if sel else None,
                           "continuation": (sel.get("chosen_settings") or {}).get("continuation") if sel else None,
                           "held": (sel.get("chosen_settings") or {}).get("held") if sel else None,
                           "extrapolated": ex.get("summary") if ex.get("any") else None,
                           "wall_s": time.perf_counter() - t0}
    return case


def target_check(case: Case, default: str = DEFAULT_METHOD, factor: float = 1.05) -> dict:
    """Whether the default method is within ``factor`` of the better of a line in T and the selected polynomial.

    Parameters
    ----------
    case : Case
    default : str
    factor : float

    Returns
    -------
    dict
        ``ok``, ``ratio`` (default / the better one) and ``winner`` (``line`` when the line is better).
    """
    r = case.results
    line = r.get("line", {}).get("rms_dps")
    poly = r.get("poly-baseline", {}).get("rms_dps")
    d = r.get(default, {}).get("rms_dps")
    if None in (line, poly, d):
        return {"ok": None, "ratio": None, "winner": None}
    best = min(line, poly)
    return {"ok": bool(d <= factor * best), "ratio": d / best, "winner": "line" if line < poly else "poly-baseline"}


def markdown(cases: list[Case], methods=METHODS) -> str:
    """The table for the validation page: held-out RMS over the bias-calibrated RMS.

    Parameters
    ----------
    cases : list of Case
    methods : sequence of str

    Returns
    -------
    str
    """
    head = (["record", "fitted -> applied"] + [f"`{m}`" for m in methods]
            + ["floor", "bias RMS (deg/s)", f"{DEFAULT_METHOD} chose", f"{DEFAULT_METHOD} / line"])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    refusals = {}
    for c in cases:
        cells = [c.record, c.direction]
        for m in methods:
            res = c.results.get(m, {})
            if "refused" in res:
                key = re.sub(r"(compensation )?method '[^']+'", "the method", res["refused"])
                refusals.setdefault(key, len(refusals) + 1)
                cells.append(f"refused [{refusals[key]}]")
            elif "ratio" in res:
                cells.append(f"{res['ratio']:.3f}")
            else:
                cells.append("")
        d, line = c.results.get(DEFAULT_METHOD, {}), c.results.get("line", {})
        vs = (f"{d['rms_dps'] / line['rms_dps']:.3f}" + (" (line wins)" if line["rms_dps"] < d["rms_dps"] else "")
              if "rms_dps" in d and "rms_dps" in line else "")
        cont = ""
        if d.get("extrapolated"):
            held = d.get("held") or []
            cont = f", {d['continuation']}" + (f" (held in {', '.join(held)})" if held else "")
        cells += [f"{c.references['floor_ratio']:.3f}", f"{c.references['bias_rms_dps']:.4g}",
                  (d.get("chosen") or "") + cont, vs]
        lines.append("| " + " | ".join(cells) + " |")
    if refusals:
        lines += [""] + [f"[{k}] {why}" for why, k in refusals.items()]
    return "\n".join(lines) + "\n"


def to_dict(cases: list[Case], skipped: dict) -> dict:
    """JSON-ready results.

    Parameters
    ----------
    cases : list of Case
    skipped : dict
        Folders left out, with the reason.

    Returns
    -------
    dict
    """
    return {"skipped": skipped, "cases": [{"record": c.record, "direction": c.direction, **c.describe(),
                                           "references": c.references, "results": c.results,
                                           "target": target_check(c)} for c in cases]}


def report(cases: list[Case], skipped: dict, methods=METHODS) -> str:
    """The whole measured-records block of the documentation: table, refusals, target check.

    Parameters
    ----------
    cases : list of Case
        Evaluated cases.
    skipped : dict
        Folders left out, with the reason.
    methods : sequence of str

    Returns
    -------
    str
        Markdown (no timings: the same data give the same text).
    """
    checks = [(c, target_check(c)) for c in cases]
    ok = [(c, t) for c, t in checks if t["ok"] is not None]
    lines = [markdown(cases, methods).rstrip("\n"), ""]
    lines.append(f"The default method (`{DEFAULT_METHOD}`) is within 1.05 x the better of a line in T and the "
                 f"selected polynomial on {sum(t['ok'] for _, t in ok)} of {len(ok)} train/test pairs"
                 + (f" (worst ratio {max(t['ratio'] for _, t in ok):.3f})" if ok else "") + ".")
    wins = [(c, t) for c, t in ok if t["winner"] == "line"]
    if wins:
        lines.append(f"The line in T has the lower held-out RMS on {len(wins)} of them: "
                     + "; ".join(f"{c.record}, {c.direction} (the default {t['ratio']:.3f} x the line)"
                                 for c, t in wins) + ".")
    else:
        lines.append("The line in T never has the lower held-out RMS.")
    for k, why in skipped.items():
        lines.append(f"`{k}` is left out: {why}.")
    return "\n".join(lines) + "\n"

