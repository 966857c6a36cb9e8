"""``fmvmg compensate RECORD.csv --method M [--train TRAIN.csv] [-o DIR] [--json]`` (docs/formats.md).

Fits the method on ``--train`` (held-out, ``in_sample: false``) or, without it, on the
record itself (``in_sample: true``), compensates the record and writes
``DIR/compensated.csv`` (``rate_dps`` compensated, ``rate_raw_dps`` the input's, other
channels copied) and ``DIR/compensation.json``. Allan numbers come from
:func:`fmvmg_sim.analysis.allan.allan_deviation` on the longest evenly sampled stretch.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from ..jsonout import strict
from ..record import Record, atomic_write_text, read_record, write_record

METHOD_NAMES = ("emd-rbf", "emd-rbf-ga", "emd-rbf-ga-kf", "vmd-wflp-cssvr", "poly-baseline", "physics")


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


def metrics(record: Record, rate_dps: np.ndarray | None = None) -> dict:
    """Allan and truth numbers of a rate series on ``record``'s time base.

    Parameters
    ----------
    record : Record
        Supplies ``time_s`` and, where present, ``rate_true_dps``.
    rate_dps : ndarray, optional
        The series to assess (default: the record's own ``rate_dps``).

    Returns
    -------
    dict
        ``arw_deg_per_sqrt_h``, ``bias_instability_deg_per_h`` (Allan minimum, as paper 000),
        ``bias_instability_ieee952_deg_per_h``, ``allan_samples`` and, with a known true rate,
        ``truth_rms_dps`` and ``residual_drift_rms_dph`` (RMS of 100 s means of the error,
        which low-pass filtering cannot shrink).
    """
    from ..analysis.allan import allan_deviation

    y = record["rate_dps"] if rate_dps is None else np.asarray(rate_dps, float)
    t = record.time_s
    seg = _uniform_stretch(t)
    ts = t[seg]
    a = allan_deviation(y[seg], (len(ts) - 1) / (ts[-1] - ts[0]))
    out = {"arw_deg_per_sqrt_h": a.arw_deg_per_sqrt_h, "bias_instability_deg_per_h": a.bias_instability_deg_per_h,
           "bias_instability_ieee952_deg_per_h": a.bias_instability_ieee952_deg_per_h,
           "allan_samples": len(ts)}
    if record.has("rate_true_dps"):
        err = y - record["rate_true_dps"]
        ok = np.isfinite(err)
        out["truth_rms_dps"] = float(np.sqrt(np.mean(err[ok] ** 2)))
        idx = np.floor((t[ok] - t[0]) / 100.0).astype(np.int64)
        _, start, cnt = np.unique(idx, return_index=True, return_counts=True)
        out["residual_drift_rms_dph"] = float(np.sqrt(np.mean((np.add.reduceat(err[ok], start) / cnt) ** 2)) * 3600)
    return out


def run(args) -> int:
    """Execute ``fmvmg compensate`` with parsed ``args``; returns the exit code."""
    from ..compensation import get_method
    from ..output import OutputFolder

    cls = get_method(args.method)
    record = read_record(args.record)
    train = read_record(args.train) if args.train else record
    outdir = Path(args.output) if args.output else Path(args.record).with_suffix("").parent / (
        Path(args.record).stem + f"-{args.method}")
    staged = OutputFolder(outdir, command="compensate")  # refused now, before the fit, if it cannot be written
    kw = {"progress": not args.no_progress} if "progress" in cls().get_params() else {}
    if "seed" in cls().get_params():
        kw["seed"] = args.seed
    comp = cls(**kw)
    t0 = time.perf_counter()
    if args.train:
        comp.fit(train)
        out = comp.transform(record)
    else:
        out = comp.fit_transform(record)
    wall = time.perf_counter() - t0
    cols = dict(record.columns)
    cols["rate_raw_dps"] = record["rate_dps"]
    cols["rate_dps"] = np.asarray(out, float)
    meta = dict(record.metadata)
    meta.update({"compensation_method": args.method, "in_sample": str(not args.train).lower(),
                 "trained_on": str(args.train or args.record), "source_record": str(args.record)})
    write_record(staged.path / "compensated.csv", Record(cols, meta))
    result = {"method": args.method, "in_sample": not args.train, "record": str(args.record),
              "train": str(args.train or args.record), "before": metrics(record), "after": metrics(record, out),
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
        b, a = result["before"], result["after"]
        print(f"{args.method} ({'in-sample' if result['in_sample'] else 'held-out'}) -> {result['output']}")
        for k in ("arw_deg_per_sqrt_h", "bias_instability_deg_per_h", "truth_rms_dps", "residual_drift_rms_dph"):
            if k in b:
                print(f"  {k:28s} before {b[k]!s:>24}  after {a[k]!s:>24}")
    return 0


def register(sub) -> None:
    """Add the ``compensate`` sub-command to the ``fmvmg`` parser."""
    p = sub.add_parser("compensate", help="temperature-drift compensation of a record",
                       description=__doc__.splitlines()[0])
    p.add_argument("record", metavar="RECORD.csv", help="record to compensate (the record format of docs/formats.md)")
    p.add_argument("--method", required=True, metavar="M",
                   help=f"compensation method, one of: {', '.join(METHOD_NAMES)}")
    p.add_argument("--train", metavar="RECORD.csv", help="fit on this record (held-out evaluation); "
                   "default: fit on RECORD itself (in-sample)")
    p.add_argument("-o", "--output", metavar="DIR", help="output folder (default: RECORD-stem-METHOD next to RECORD)")
    p.add_argument("--seed", type=int, default=0, help="seed of the method's random choices (default 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)

