"""The diagnosis scored on labelled records the project did not make (``fmvmg diagnose-independent``).

A folder of records (``case_XXX.csv`` or ``.csv.gz``, the record format) and their truth (``labels.json``: per case
``effects`` ``{name: params}``, empty for a null unit, and ``strength`` per effect, ``clear``, ``detectable`` or
``near_or_below_noise``) is diagnosed against one or more nominal scenarios, each record in its own process; each
outcome is scored against its label after every diagnosis has returned:

* a null unit is right when the verdict is ``none``;
* a single effect is right when it is accepted first, or named in the ambiguity set of the accepted effect;
* a pair is right when the accepted set is the truth;
* every accepted deterministic effect is checked against the acceptance floor on its held-out shrink
  (:data:`~fmvmg_sim.diagnosis.criteria.SHRINK_FLOOR`);
* every true effect's size is divided by the detection limit the report states for it on that record (the smallest
  size attributed with probability 0.9 once the scenario's stated uncertainty is calibrated; :data:`LIMIT_PARAMS`
  translates the labels' parameters): below 1, the record, read through that scenario, can hide the effect.

:func:`format_table` gives the one table docs/diagnosis_guide.md shows.
"""

from __future__ import annotations

import json
import sys
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..diagnosis.criteria import SHRINK_FLOOR
from ..diagnosis.pipeline import N_NULL, diagnose
from ..diagnosis.report import write_report
from ..errors import InputError
from ..record import atomic_write_text

#: Noise-level effects (their report row has no held-out shrink of the deterministic gap).
NOISE_LEVEL = ("quantization", "flicker_noise")

#: A labelled effect's size in the parameter of the report's detection limit: ``{effect: (label parameter, limit
#: parameter, factor)}``, limit-parameter value = factor x label value. A factor of ``None`` is the scenario's
#: rate-output offset per fF of feedthrough capacitance (:func:`feedthrough_dps_per_fF`), which turns a label's
#: feedthrough magnitude in deg/s at 25 C into the capacitance the limit is stated in. Noise-level effects have
#: no such limit (they are judged by their Allan band and the output lattice).
LIMIT_PARAMS = {
    "thermal_lag": ("tau_s", "tau_s", 1.0),
    "thermal_hysteresis": ("quad_rel_amplitude", "quad_rel", 1.0),
    "temperature_rate": ("g_dps_per_K_per_s", "g_dph_per_K_per_min", 60.0),   # 1 deg/s per K/s = 60 deg/h per K/min
    "demod_phase_drift": ("kappa_rad_per_K", "kappa_urad_per_K", 1e6),
    "quadrature_drift": ("beta_per_K", "beta_per_K", 1.0),
    "q_factor_drift": ("gamma_per_K", "q_tc_per_K", 1.0),
    "mode_split_drift": ("split_Hz_per_K", "split_Hz_per_K", 1.0),
    "feedthrough": ("magnitude_dps", "c_ft_fF", None),
    "duffing": ("k3_rel", "k3_rel", 1.0),
    "reference_drift": ("vref_ppm_per_K", "vref_tc_per_K", 1e-6),
    "stress_relaxation": ("quad_rel", "quad_rel", 1.0),
}


def load_labels(folder: Path) -> dict:
    """The labels of a folder of independent records, each with its record file.

    Parameters
    ----------
    folder : Path
        Holds ``labels.json`` and the records it names (``<case>.csv`` or ``<case>.csv.gz``).

    Returns
    -------
    dict
        ``{case: label}``, each label with ``record`` (the file) added.

    Raises
    ------
    InputError
        No ``labels.json``, not JSON, a case without ``effects``, or a case whose record is missing.
    """
    path = Path(folder) / "labels.json"
    if not path.is_file():
        raise InputError("no labels.json (expected {case: {effects: {...}, strength: {...}}})", str(folder))
    try:
        labels = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"not JSON ({exc})", str(path)) from None
    if not isinstance(labels, dict):
        raise InputError("expected an object of cases", str(path))
    out = {}
    for case, lab in labels.items():
        if not isinstance(lab, dict) or not isinstance(lab.get("effects"), dict):
            raise InputError("a case without an 'effects' table", f"{path}: {case}")
        rec = next((Path(folder) / f"{case}{ext}" for ext in (".csv", ".csv.gz")
                    if (Path(folder) / f"{case}{ext}").is_file()), None)
        if rec is None:
            raise InputError(f"no record {case}.csv or {case}.csv.gz beside the labels", f"{path}: {case}")
        out[case] = dict(lab, record=str(rec))
    return out


def kind(label: dict) -> str:
    """``"null"``, ``"single"`` or ``"pair"`` (by the number of true effects).

    Parameters
    ----------
    label : dict

    Returns
    -------
    str
    """
    return {0: "null", 1: "single"}.get(len(label["effects"]), "pair")


def feedthrough_dps_per_fF(scenario) -> float:
    """The scenario's zero-rate output per fF of drive-to-sense feedthrough capacitance, at 25 C, noise off.

    Parameters
    ----------
    scenario : str or path-like
        A nominal scenario (name or file).

    Returns
    -------
    float
        deg/s per fF (the settled output with 1 fF minus the one without).
    """
    from ..api import simulate
    base = ["scenario.duration_s=0.5", "temperature.start_C=25", "effects.feedthrough.tc_per_K=0"] \
        + [f"noise.{n}=false" for n in ("brownian", "electronic", "flicker", "quantization", "rate_random_walk")]
    settled = [float(np.mean(simulate(str(scenario), overrides=base + [f"effects.feedthrough.c_ft_fF={c}"])
                             ["rate_dps"][-3:])) for c in (0.0, 1.0)]
    return settled[1] - settled[0]


def limit_ratios(label: dict, report: dict, dps_per_fF: float | None = None) -> dict:
    """Each true effect's size over the detection limit the report states for it on the record.

    Parameters
    ----------
    label : dict
        ``effects`` ``{name: params}`` in the labels' parameters (:data:`LIMIT_PARAMS`).
    report : dict
        The JSON report (its ``detection_limits``).
    dps_per_fF : float, optional
        :func:`feedthrough_dps_per_fF` of the scenario (without it a feedthrough's ratio is not known).

    Returns
    -------
    dict
        ``{effect: |size| / limit}``, ``None`` where the label or the report lacks what the ratio needs.
    """
    limits = (report.get("detection_limits") or {}).get("effects") or {}
    out = {}
    for name, params in label["effects"].items():
        out[name] = None
        if name not in LIMIT_PARAMS:
            continue
        label_param, limit_param, factor = LIMIT_PARAMS[name]
        if factor is None:
            factor = 1.0 / dps_per_fF if dps_per_fF else None
        value = (params or {}).get(label_param)
        limit = ((limits.get(name) or {}).get("params") or {}).get(limit_param)
        if factor is not None and isinstance(value, (int, float)) and isinstance(limit, (int, float)) and limit > 0:
            out[name] = abs(value * factor) / limit
    return out


def score_case(label: dict, report: dict, dps_per_fF: float | None = None) -> dict:
    """One record's outcome against its label.

    Parameters
    ----------
    label : dict
        ``effects`` and, optionally, ``strength``.
    report : dict
        The JSON report, or ``{"error": ...}``.
    dps_per_fF : float, optional
        The scenario's :func:`feedthrough_dps_per_fF`, for a feedthrough's :func:`limit_ratios`.

    Returns
    -------
    dict
        ``truth``, ``strength``, ``kind``, ``verdict``, ``accepted``, ``ambiguous_with``, ``shrink`` (of each
        accepted deterministic effect), ``right``, ``below_floor`` (accepted effects whose shrink is below the
        floor), ``limit_ratio`` (:func:`limit_ratios`), ``rules_fired``, ``error``.
    """
    truth = sorted(label["effects"])
    row = {"truth": truth, "strength": dict(label.get("strength") or {}), "kind": kind(label)}
    if "error" in report:
        return dict(row, verdict=None, accepted=[], ambiguous_with={}, shrink={}, right=False, below_floor=[],
                    limit_ratio={t: None for t in truth}, rules_fired=[], error=report["error"])
    acc = list(report["accepted"])
    amb = report.get("ambiguous_with") or {}
    rows = {r["effect"]: r for r in report.get("ranked", [])}
    shrink = {a: rows.get(a, {}).get("shrink") for a in acc if a not in NOISE_LEVEL}
    if row["kind"] == "null":
        right = report["verdict"] == "none" and not acc
    elif row["kind"] == "single":
        t = truth[0]
        right = bool(acc[:1] == [t] or (acc and t in amb.get(acc[0], [])))
    else:
        right = sorted(acc) == truth
    below = [a for a, s in shrink.items() if s is None or s < SHRINK_FLOOR]
    return dict(row, verdict=report["verdict"], accepted=acc, ambiguous_with=amb, shrink=shrink, right=bool(right),
                below_floor=below, limit_ratio=limit_ratios(label, report, dps_per_fF),
                rules_fired=[r["rule"] for r in report.get("rules_fired", [])], error=None)


def summary(rows: dict) -> dict:
    """Rates over the scored records.

    Parameters
    ----------
    rows : dict
        ``{case: score_case(...)}``.

    Returns
    -------
    dict
        ``{group: {"right": k, "cases": n}}`` for ``null``, ``single_clear`` (single effects labelled clear),
        ``single_clear_above_limit`` (those whose size is at least the report's detection limit), ``single`` and
        ``pair``; ``accepted_below_floor`` (accepted effects whose held-out shrink is below the
        floor, over all records) and ``errors``.
    """
    def part(sel):
        v = [r for r in rows.values() if sel(r)]
        return {"right": sum(r["right"] for r in v), "cases": len(v)}

    def clear(r):
        return r["kind"] == "single" and bool(r["strength"]) and all(s == "clear" for s in r["strength"].values())
    return {"null": part(lambda r: r["kind"] == "null"),
            "single_clear": part(clear),
            "single_clear_above_limit": part(lambda r: clear(r) and all(
                x is not None and x >= 1.0 for x in r.get("limit_ratio", {}).values())),
            "single": part(lambda r: r["kind"] == "single"),
            "pair": part(lambda r: r["kind"] == "pair"),
            "accepted_below_floor": sum(len(r["below_floor"]) for r in rows.values()),
            "errors": sum(r["error"] is not None for r in rows.values())}


def _diagnose_one(args: tuple) -> dict:
    """Worker: diagnose one record against one scenario and write its report (the label is not read here)."""
    record, scenario, out_dir, n_null = args
    warnings.simplefilter("ignore")
    try:
        rep = diagnose(record, scenario, n_null=n_null, progress=False, log=lambda m: None)
    except Exception as exc:  # a failed diagnosis is scored as a failure, not hidden
        return {"error": f"{type(exc).__name__}: {exc}"}
    return write_report(rep, Path(out_dir))


def run_independent(folder: Path, scenarios: list, out: Path, cases: list | None = None, workers: int = 2,
                    n_null: int = N_NULL, progress: bool = True) -> dict:
    """Diagnose every labelled record against every scenario and score the outcomes.

    Parameters
    ----------
    folder : Path
        The records and ``labels.json`` (:func:`load_labels`).
    scenarios : list of str
        Nominal scenarios (names or files).
    out : Path
        Reports go to ``out/<scenario>/<case>/``; ``scores.json`` and ``table.md`` to ``out``.
    cases : list of str, optional
        A subset of the cases (default all).
    workers : int, optional
        Processes.
    n_null : int, optional
        Null re-simulations per diagnosis.
    progress : bool, optional

    Returns
    -------
    dict
        ``{"scenarios": {name: {"rows": {case: row}, "summary": {...}}}, "shrink_floor": ...}``.
    """
    labels = load_labels(folder)
    if cases:
        unknown = [c for c in cases if c not in labels]
        if unknown:
            raise InputError(f"no such case(s) {unknown} in labels.json", str(folder))
        labels = {c: labels[c] for c in cases}
    jobs = [(labels[c]["record"], str(s), str(Path(out) / Path(str(s)).stem / c), n_null)
            for s in scenarios for c in labels]
    with ProcessPoolExecutor(max_workers=max(1, workers)) as ex:
        reports = list(tqdm(ex.map(_diagnose_one, jobs), total=len(jobs), disable=not progress, file=sys.stderr,
                            desc="independent records"))
    result = {"folder": str(folder), "shrink_floor": SHRINK_FLOOR, "scenarios": {}}
    it = iter(reports)
    with_ft = any("feedthrough" in lab["effects"] for lab in labels.values())
    for s in scenarios:
        ft = feedthrough_dps_per_fF(s) if with_ft else None
        rows = {c: score_case(labels[c], next(it), ft) for c in labels}
        result["scenarios"][Path(str(s)).stem] = {"rows": rows, "summary": summary(rows)}
    atomic_write_text(Path(out) / "scores.json", json.dumps(result, indent=1, default=float) + "\n")
    atomic_write_text(Path(out) / "table.md", format_table(result))
    return result


def accepted_cell(row: dict) -> str:
    """A table cell of a scored row: each accepted effect with its held-out shrink and its look-alikes.

    Parameters
    ----------
    row : dict
        From :func:`score_case`.

    Returns
    -------
    str
    """
    if row["error"]:
        return f"error: {row['error']}"
    parts = []
    for a in row["accepted"]:
        s = row["shrink"].get(a)
        amb = row["ambiguous_with"].get(a)
        parts.append(a + (f" ({s:.2f})" if s is not None else "") + (f" ~ {', '.join(amb)}" if amb else ""))
    return "; ".join(parts) or "-"


def ratio_cell(row: dict) -> str:
    """A table cell of a scored row: each true effect's size over the report's detection limit (:func:`limit_ratios`).

    Parameters
    ----------
    row : dict
        From :func:`score_case`.

    Returns
    -------
    str
    """
    r = row.get("limit_ratio") or {}
    return ", ".join("n/a" if t in NOISE_LEVEL else "?" if r.get(t) is None else f"{r[t]:.2g}"
                     for t in row["truth"]) or "-"


def format_table(result: dict, numbered: bool = False) -> str:
    """The Markdown table of a run: one row per record, per scenario its verdict, accepted effects (held-out
    shrink, look-alikes), each true effect's size over its detection limit and whether it is right, then the
    rates.

    Parameters
    ----------
    result : dict
        From :func:`run_independent`.
    numbered : bool, optional
        Rows numbered 1, 2, ... instead of named by their record.

    Returns
    -------
    str
    """
    names = list(result["scenarios"])
    cases = list(next(iter(result["scenarios"].values()))["rows"]) if names else []
    head = "| record | truth (strength) | " + " | ".join(
        f"{n}: verdict | accepted (shrink) ~ look-alikes | size / limit | right" for n in names) + " |"
    L = [head, "|" + "---|" * (2 + 4 * len(names))]
    for i, c in enumerate(cases, 1):
        r0 = result["scenarios"][names[0]]["rows"][c]
        truth = ", ".join(f"{t} ({r0['strength'].get(t, '?')})" for t in r0["truth"]) or "none (null unit)"
        cells = []
        for n in names:
            r = result["scenarios"][n]["rows"][c]
            cells += [r["verdict"] or "-", accepted_cell(r), ratio_cell(r), "yes" if r["right"] else "**no**"]
        L.append(f"| {i if numbered else c} | {truth} | " + " | ".join(cells) + " |")
    L += ["", "| scenario | null units 'none' | clear single effect found | found when at or above its limit "
          "| all single effects found | pairs exact "
          f"| accepted with shrink below {result['shrink_floor']:g} | errors |", "|---|---|---|---|---|---|---|---|"]
    for n in names:
        s = result["scenarios"][n]["summary"]
        f = lambda d: f"{d['right']} / {d['cases']}"  # noqa: E731
        above = f(s["single_clear_above_limit"]) if "single_clear_above_limit" in s else "-"
        L.append(f"| {n} | {f(s['null'])} | {f(s['single_clear'])} | {above} | {f(s['single'])} | {f(s['pair'])} | "
                 f"{s['accepted_below_floor']} | {s['errors']} |")
    return "\n".join(L) + "\n"
