"""``fmvmg diagnose-independent FOLDER``: the diagnosis scored on labelled records the project did not make."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .options import add_json, add_output


def register(sub) -> None:
    """Add the ``diagnose-independent`` sub-command to ``sub`` (an ``argparse._SubParsersAction``)."""
    p = sub.add_parser("diagnose-independent", help="score the diagnosis on labelled records made elsewhere",
                       description=(
                           "Diagnose every record of FOLDER (case_XXX.csv or .csv.gz beside a labels.json giving each "
                           "case's true effects and their strength) against each --scenario, then score: null units "
                           "right when the verdict is 'none', a single effect when it is accepted first or named in "
                           "the accepted effect's ambiguity set, a pair when the accepted set is exact. Writes "
                           "DIR/table.md (one row per record), DIR/scores.json and every report."))
    p.add_argument("folder", help="folder of labelled records (labels.json beside the records)")
    p.add_argument("--scenario", action="append", default=None,
                   help="nominal scenario (repeat for several; default nominal_a)")
    add_output(p, "out/diagnose_independent")
    p.add_argument("--cases", default=None, metavar="CASE[,CASE...]", help="only these cases (default all)")
    p.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    p.add_argument("--null-runs", type=int, default=None, help="null re-simulations per diagnosis (default 6)")
    add_json(p, "the scores")
    p.set_defaults(func=main)


def main(args) -> int:
    """Run the sub-command with the parsed ``args``; returns the exit code."""
    from ..errors import InputError
    from ..output import OutputFolder
    from ..paths import resolve_scenario
    from ..validation.independent import load_labels, run_independent
    from ..diagnosis.pipeline import N_NULL
    folder = Path(args.folder)
    if not folder.is_dir():
        raise InputError("not a folder", str(folder))
    load_labels(folder)  # bad labels refused before anything runs
    scenarios = []
    for s in args.scenario or ["nominal_a"]:
        p = resolve_scenario(s)
        if not Path(p).is_file():
            raise InputError("scenario file not found", str(s))
        scenarios.append(str(p))
    if args.workers < 1:
        raise InputError("must be >= 1", "--workers")
    if args.null_runs is not None and args.null_runs < 2:
        raise InputError("needs at least 2 null re-simulations", "--null-runs")
    cases = [c.strip() for c in args.cases.split(",") if c.strip()] if args.cases else None
    staged = OutputFolder(Path(args.out), command="diagnose-independent")
    res = run_independent(folder, scenarios, staged.path, cases, args.workers, args.null_runs or N_NULL)
    staged.commit()
    if args.json:
        sys.stdout.write(json.dumps({n: v["summary"] for n, v in res["scenarios"].items()}) + "\n")
    else:
        sys.stderr.write((Path(args.out) / "table.md").read_text())
    return 0
