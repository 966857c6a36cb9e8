"""``fmvmg compensate RECORD.csv [--method M] [--train TRAIN.csv] [-o DIR] [--json]`` (docs/formats.md).

Fits the method (default ``poly-baseline``: the polynomial in T, with or without dT/dt,
chosen by forward-chained validation) on ``--train`` (held-out, ``in_sample: false``) or,
without it, on the record itself (``in_sample: true``), compensates the record and writes
``DIR/compensated.csv`` (``rate_dps`` compensated, ``rate_raw_dps`` the input's, other
channels copied) and ``DIR/compensation.json``. Beside the contract's keys the JSON holds
``selection`` (what the method chose and every option's validation score), ``extrapolation``
(how far the record leaves the training range, and which terms that touched) and, with
``--train``, ``baselines`` (the held-out RMS of a bias calibration, a line in T and the
record's white-noise floor beside the method's, and which one wins). Allan numbers come from
:func:`fmvmg_sim.analysis.allan.allan_deviation` on the longest evenly sampled stretch; a
figure read where the curve has no valid region is marked (``allan_validity``).
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from ..jsonout import strict
from ..record import Record, atomic_write_text, read_record, write_record
from .options import add_json, add_no_progress, add_output

METHOD_NAMES = ("poly-baseline", "line", "bias", "physics", "emd-rbf", "emd-rbf-ga", "emd-rbf-ga-kf", "vmd-wflp-cssvr")
#: The method used when ``--method`` is not given: on every measured record the project holds,
#: the selected polynomial is within a few per cent of the best of the methods (docs/compensation_results.md).
DEFAULT_METHOD = "poly-baseline"
#: The Allan bias instability is read as valid only at tau >= this factor x the filter time constant.
TAU_FACTOR = 10.0


def _uniform_stretch(t_s: np.ndarray) -> slice:
    """Longest run of samples whose steps lie within 1 % of the median step."""
    dt = np.diff(t_s)
    ok = np.abs(dt - np.median(dt)) <= 0.01 * np.median(dt)
    best, start, best_len = slice(0, len(t_s)), 0, 0
    for i, good in enumerate(np.append(ok, False)):
        if not good:
            if i + 1 - start > best_len:
                best, best_len = slice(start, i + 1), i + 1 - start
            start = i + 1
    return best


def metrics(record: Record, rate_dps: np.ndarray | None = None, filter_time_constant_s: float = 0.0) -> dict:
    """Allan and truth numbers of a rate series on ``record``'s time base.

    Parameters
    ----------
    record : Record
        Supplies ``time_s`` and, where present, ``rate_true_dps``.
    rate_dps : ndarray, optional
        The series to assess (default: the record's own ``rate_dps``).
    filter_time_constant_s : float, optional
        The longest time constant of the filtering that made the series (0 for a subtraction).

    Returns
    -------
    dict
        ``arw_deg_per_sqrt_h``, ``bias_instability_deg_per_h`` (Allan minimum, as paper 000),
        ``bias_instability_ieee952_deg_per_h``, ``bias_instability_tau_s``, ``allan_samples``,
        ``allan_validity`` (:func:`allan_validity`) and, with a known true rate,
        ``truth_rms_dps`` and ``residual_drift_rms_dph`` (RMS of 100 s means of the error,
        which low-pass filtering cannot shrink).
    """
    from ..analysis.allan import allan_deviation

    y = record["rate_dps"] if rate_dps is None else np.asarray(rate_dps, float)
    t = record.time_s
    ok = np.isfinite(y)
    seg = _uniform_stretch(t[ok])
    ts, ys = t[ok][seg], y[ok][seg]
    a = allan_deviation(ys, (len(ts) - 1) / (ts[-1] - ts[0]))
    out = {"arw_deg_per_sqrt_h": a.arw_deg_per_sqrt_h, "bias_instability_deg_per_h": a.bias_instability_deg_per_h,
           "bias_instability_ieee952_deg_per_h": a.bias_instability_ieee952_deg_per_h,
           "bias_instability_tau_s": a.tau_min_s, "allan_samples": len(ts),
           "allan_validity": allan_validity(a, filter_time_constant_s, (ts[-1] - ts[0]) / (t[-1] - t[0]))}
    if record.has("rate_true_dps"):
        err = y - record["rate_true_dps"]
        ok = np.isfinite(err)
        out["truth_rms_dps"] = float(np.sqrt(np.mean(err[ok] ** 2)))
        idx = np.floor((t[ok] - t[0]) / 100.0).astype(np.int64)
        _, start, cnt = np.unique(idx, return_index=True, return_counts=True)
        out["residual_drift_rms_dph"] = float(np.sqrt(np.mean((np.add.reduceat(err[ok], start) / cnt) ** 2)) * 3600)
    return out


def allan_validity(a, filter_time_constant_s: float = 0.0, coverage: float = 1.0) -> dict:
    """Whether the ARW and bias-instability readings of an Allan result stand on a valid region.

    The ARW is valid only where the curve has a -1/2 region (IEEE 952). The Allan minimum is
    a bias instability only when the curve reaches it from a white-noise region and at tau at
    least :data:`TAU_FACTOR` times the longest filter time constant of what made the series:
    a low-passed output has a minimum at the shortest tau that says nothing of the sensor.

    Parameters
    ----------
    a : AllanResult
    filter_time_constant_s : float
        Longest filter time constant of the method (0: nothing filtered).
    coverage : float
        Fraction of the record's duration the analysed even stretch covers.

    Returns
    -------
    dict
        ``arw_valid``, ``bias_instability_valid`` and the ``reasons`` when not.
    """
    reasons = {}
    if a.N is None:
        reasons["arw"] = a.white.reason or "no -1/2 (white noise) region"
    why = []
    if a.N is None:
        why.append("the curve has no white-noise (-1/2) region left of its minimum, so the minimum may be "
                   "shaped by filtering (the sensor's or the method's) rather than by a flicker floor")
    if a.tau_min_s is not None and a.tau_min_s < TAU_FACTOR * filter_time_constant_s:
        why.append(f"read at tau = {a.tau_min_s:.3g} s, inside the reach of the method's filtering "
                   f"(tau < {TAU_FACTOR:g} x its {filter_time_constant_s:.3g} s time constant)")
    if a._i_min >= 0 and a.tau_min_s == a.taus_s[0] and a.N is None:
        why.append("the minimum is at the shortest tau (the curve rises from there)")
    if coverage < 0.5:
        why.append(f"read on the longest evenly sampled stretch, {100 * coverage:.2g} % of the record "
                   "(a record of bursts or with gaps)")
    if why:
        reasons["bias_instability"] = "; ".join(why)
    return {"arw_valid": "arw" not in reasons, "bias_instability_valid": "bias_instability" not in reasons,
            "reasons": reasons}


def _filter_tau(comp) -> float:
    for attr in ("transform_diagnostics_", "diagnostics_", "fit_diagnostics_"):
        d = getattr(comp, attr, None) or {}
        if isinstance(d, dict) and d.get("filter_time_constant_s") is not None:
            return float(d["filter_time_constant_s"])
    return 0.0


def _report_blocks(comp) -> dict:
    """The selection and extrapolation reports of a fitted-and-applied compensator."""
    fit = getattr(comp, "fit_diagnostics_", None) or getattr(comp, "diagnostics_", None) or {}
    tr = getattr(comp, "transform_diagnostics_", None) or {}
    return {"selection": comp.selection_report(), "extrapolation": tr.get("extrapolation"),
            "notes": list(fit.get("notes") or []) + list(tr.get("notes") or [])}


def run(args) -> int:
    """Execute ``fmvmg compensate`` with parsed ``args``; returns the exit code."""
    from ..compensation import get_method
    from ..compensation.baselines import compare
    from ..output import OutputFolder

    cls = get_method(args.method)
    record = read_record(args.record)
    train = read_record(args.train) if args.train else record
    outdir = Path(args.out) if args.out else Path(args.record).with_suffix("").parent / (
        Path(args.record).stem + f"-{args.method}")
    staged = OutputFolder(outdir, command="compensate")  # refused now, before the fit, if it cannot be written
    kw = {"progress": not args.no_progress} if "progress" in cls().get_params() else {}
    if "seed" in cls().get_params():
        kw["seed"] = args.seed
    comp = cls(**kw)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        compensated = comp.fit(train).transform(record) if args.train else comp.fit_transform(record)
    wall = time.perf_counter() - t0
    out = compensated["rate_dps"]
    compensated.metadata.update({"in_sample": str(not args.train).lower(),
                                 "trained_on": str(args.train or args.record), "source_record": str(args.record)})
    write_record(staged.path / "compensated.csv", compensated)
    blocks = _report_blocks(comp)
    blocks["notes"] = list(dict.fromkeys([str(w.message) for w in caught] + blocks["notes"]))
    if args.train:
        baselines = {"held_out": True, **compare(args.method, out, train, record)}
    else:
        baselines = {"held_out": False, "note": "fitted on the record itself (in-sample): give --train for a "
                                                "held-out comparison with a bias calibration and a line in T"}
    result = {"method": args.method, "in_sample": not args.train, "record": str(args.record),
              "train": str(args.train or args.record), "before": metrics(record),
              "after": metrics(record, out, _filter_tau(comp)), **blocks, "baselines": baselines,
              "wall_s": round(wall, 2), "output": str(outdir / "compensated.csv"),
              "fit_diagnostics": getattr(comp, "fit_diagnostics_", getattr(comp, "diagnostics_", None)),
              "transform_diagnostics": getattr(comp, "transform_diagnostics_", None)}
    result = strict(result)
    text = json.dumps(result, indent=1)
    atomic_write_text(staged.path / "compensation.json", text + "\n")
    staged.commit()
    if args.json:
        sys.stdout.write(json.dumps(result) + "\n")
    else:
        sys.stdout.write(human_report(result))
    return 0


def _mark(side: dict, key: str) -> str:
    v = side.get(key)
    val = "n/a" if v is None else f"{v:.4g}"
    valid = side.get("allan_validity") or {}
    if key == "bias_instability_deg_per_h" and not valid.get("bias_instability_valid", True):
        return val + " (not valid*)"
    if key == "arw_deg_per_sqrt_h" and v is None and not valid.get("arw_valid", True):
        return "not valid*"
    return val


def human_report(result: dict) -> str:
    """The plain-text report ``fmvmg compensate`` prints without ``--json``.

    Parameters
    ----------
    result : dict
        The JSON object of the run.

    Returns
    -------
    str
    """
    b, a = result["before"], result["after"]
    lines = [f"{result['method']} ({'in-sample' if result['in_sample'] else 'held-out'}) -> {result['output']}"]
    for k in ("arw_deg_per_sqrt_h", "bias_instability_deg_per_h", "truth_rms_dps", "residual_drift_rms_dph"):
        if k in b:
            lines.append(f"  {k:28s} before {_mark(b, k):>22}  after {_mark(a, k):>22}")
    rb = (b.get("allan_validity") or {}).get("reasons") or {}
    ra = (a.get("allan_validity") or {}).get("reasons") or {}
    for what in dict.fromkeys(list(rb) + list(ra)):
        if rb.get(what) == ra.get(what):
            lines.append(f"  * not valid before or after, {what.replace('_', ' ')}: {ra[what]}")
        else:
            for side, r in (("before", rb), ("after", ra)):
                if what in r:
                    lines.append(f"  * not valid {side}, {what.replace('_', ' ')}: {r[what]}")
    sel = result.get("selection")
    if sel:
        lines.append(f"  model chosen by chained validation: {sel['chosen']} "
                     f"({len(sel['candidates'])} options scored, {len(sel['folds'])} folds)")
    ex = result.get("extrapolation")
    if ex and ex.get("any"):
        lines.append(f"  extrapolation: {ex.get('summary') or ', '.join(ex['terms_extrapolated'])}")
    base = result.get("baselines") or {}
    if base.get("held_out"):
        rms = base["rms_dps"]
        lines.append("  held-out RMS (deg/s): " + ", ".join(f"{k} {v:.4g}" for k, v in rms.items() if v is not None))
        lines.append(f"  {base['verdict']}")
    for n in result.get("notes") or []:
        lines.append(f"  note: {n}")
    return "\n".join(lines) + "\n"


def register(sub) -> None:
    """Add the ``compensate`` sub-command to the ``fmvmg`` parser."""
    p = sub.add_parser("compensate", help="temperature-drift compensation of a record",
                       description=__doc__.splitlines()[0])
    p.add_argument("record", metavar="RECORD.csv", help="record to compensate (the record format of docs/formats.md)")
    p.add_argument("--method", default=DEFAULT_METHOD, metavar="M",
                   help=f"compensation method, one of: {', '.join(METHOD_NAMES)} (default {DEFAULT_METHOD}: "
                        "the polynomial in T chosen by validation)")
    p.add_argument("--train", metavar="RECORD.csv", help="fit on this record (held-out evaluation); "
                   "default: fit on RECORD itself (in-sample)")
    add_output(p, None, "output folder (default: RECORD-stem-METHOD next to RECORD)")
    p.add_argument("--seed", type=int, default=0, help="seed of the method's random choices (default 0)")
    add_no_progress(p)
    add_json(p, "the result")
    p.set_defaults(func=run)

