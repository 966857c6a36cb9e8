"""``fmvmg diagnose RECORD.csv --scenario NOMINAL.toml``: where the sim-to-real gap lies, which effect causes it."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .options import add_json, add_no_plots, add_no_progress, add_output, output_dir, progress


def register(sub) -> None:
    """Add the ``diagnose`` sub-command to ``sub`` (an ``argparse._SubParsersAction``)."""
    p = sub.add_parser("diagnose", help="sim-to-real gap diagnosis of a record", description=(
        "Calibrate the nominal model on a training window, localise the gap against a re-simulated null, "
        "attribute it to library effects on forward-chained held-out blocks, and report the held-out gap "
        "shrink. Writes DIR/report.json (docs/formats.md), DIR/report.md and PNG plots."))
    p.add_argument("record", help="record CSV (the record format of docs/formats.md)")
    p.add_argument("--scenario", required=True, help="nominal scenario TOML (device, circuit, noise), "
                   "e.g. scenarios/nominal_a.toml")
    add_output(p, None, "output folder (default: out/diagnose_<record name>)")
    add_json(p, "the report")
    p.add_argument("--null-runs", type=int, default=None,
                   help="null re-simulations (default 6; with fewer than 4 only a very large gap is located, and "
                        "nothing is attributed without one)")
    p.add_argument("--seed", type=int, default=0, help="seed of the null re-simulations")
    add_no_plots(p)
    add_no_progress(p)
    p.set_defaults(func=main)


def main(args) -> int:
    """Run the sub-command with the parsed ``args``; returns the exit code."""
    from ..diagnosis.pipeline import N_NULL, diagnose
    from ..diagnosis.report import write_report
    from ..errors import InputError
    from ..output import OutputFolder
    if args.null_runs is not None and args.null_runs < 2:
        raise InputError("needs at least 2 null re-simulations", "--null-runs")
    out = output_dir(args, Path("out") / f"diagnose_{Path(args.record).stem}")
    staged = OutputFolder(out, command="diagnose")  # refused now, before the diagnosis, if unwritable
    rep = diagnose(args.record, args.scenario, n_null=args.null_runs or N_NULL, seed=args.seed,
                   progress=progress(args))
    cj = write_report(rep, staged.path)
    if not args.no_plots:
        from ..diagnosis.plots import plot_all
        plot_all(rep, staged.path)
    staged.commit()
    if args.json:
        sys.stdout.write(json.dumps(cj) + "\n")
    else:
        sys.stderr.write(f"fmvmg: diagnose: verdict {cj['verdict']}"
                         + (f", accepted {cj['accepted']}" if cj["accepted"] else "")
                         + (f", ambiguous with {cj['ambiguous_with']}" if cj["ambiguous_with"] else "")
                         + f"; wrote {out}/report.json and report.md ({cj['wall_time_s']:.1f} s)\n")
    return 0
