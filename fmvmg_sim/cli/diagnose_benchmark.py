"""``fmvmg diagnose-benchmark``: the diagnosis checked on simulated cases whose effects are withheld."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .options import add_json, add_output


def register(sub) -> None:
    """Add the ``diagnose-benchmark`` sub-command to ``sub`` (an ``argparse._SubParsersAction``)."""
    p = sub.add_parser("diagnose-benchmark", help="score the diagnosis on labelled simulated cases", description=(
        "Generate labelled cases (nominal parameters perturbed within tolerance; ~20 % null, ~55 % one effect, "
        "~25 % two effects; SNR from below to above the detection limit; random temperature profiles), keep the "
        "labels in a separate folder, diagnose every case on Dask (a LocalCluster unless --scheduler) and score."))
    p.add_argument("--cases", type=int, default=20, help="number of cases (default 20)")
    p.add_argument("--seed", type=int, default=0, help="case seed")
    p.add_argument("--scheduler", default=None, help="address of a running Dask scheduler")
    p.add_argument("--scenario", default=None, help="nominal scenario (default scenarios/nominal_a.toml)")
    add_output(p, "out/diagnose_benchmark")
    p.add_argument("--duration-h", type=float, default=3.0, help="case record length in hours (default 3)")
    p.add_argument("--rate-hz", type=float, default=1.0, help="case output rate (default 1 Hz)")
    p.add_argument("--null-runs", type=int, default=None,
                   help="null re-simulations per diagnosis (default 6, as fmvmg diagnose)")
    p.add_argument("--workers", type=int, default=2, help="LocalCluster workers (default 2)")
    p.add_argument("--effects", default=None, metavar="NAME[,NAME...]",
                   help="draw effects only from these (default: the whole library)")
    p.add_argument("--mix", default="default", choices=("default", "single", "pair", "null"),
                   help="default: ~20 %% null, ~55 %% one effect, ~25 %% two; single: one effect each; "
                        "pair: two effects each; null: no effect (the false-alarm rate alone)")
    p.add_argument("--snr-min", type=float, default=1.0, help="least signature SNR target (default 1)")
    p.add_argument("--snr-max", type=float, default=1000.0, help="largest signature SNR target (default 1000)")
    p.add_argument("--ool-fraction", type=float, default=0.0, metavar="F",
                   help="fraction of out-of-library cases (a bias wander or step no library effect makes; the "
                        "right verdict is 'unexplained'); default 0, the issue's mix")
    p.add_argument("--cases-from", default=None, metavar="DIR",
                   help="diagnose again the stored cases (and labels) of an earlier run's output folder with "
                        "the current code, instead of generating cases (the generation options are then unused); "
                        "when DIR holds its scores, the outcomes are compared case by case")
    add_json(p, "the scores")
    p.set_defaults(func=main)


def main(args) -> int:
    """Run the sub-command with the parsed ``args``; returns the exit code."""
    from ..validation.benchmark import run_benchmark
    from ..validation.cases import CaseMix, MixError
    from ..errors import InputError
    from ..output import OutputFolder
    from ..paths import resolve_scenario
    from ..diagnosis.null import N_NULL
    if args.cases < 1:
        raise InputError("must be >= 1", "--cases")
    if args.null_runs is not None and args.null_runs < 2:
        raise InputError("needs at least 2 null re-simulations", "--null-runs")
    if args.duration_h * 3600 < 3600:
        raise InputError("cases must be at least 1 h long (training plus held-out windows)", "--duration-h")
    scn = str(resolve_scenario(args.scenario or "nominal_a"))
    if not Path(scn).is_file():
        raise InputError("file not found", scn)
    effects = [e.strip() for e in args.effects.split(",") if e.strip()] if args.effects is not None else None
    try:
        mix = CaseMix.build(effects, args.mix, args.snr_min, args.snr_max, args.ool_fraction)
    except MixError as exc:
        flag = {"effects": "--effects", "kind": "--mix", "snr": "--snr-min/--snr-max",
                "ool": "--ool-fraction"}[exc.field]
        raise InputError(str(exc), flag) from None
    cases_from = None
    if args.cases_from is not None:
        from ..validation.benchmark import stored_cases
        cases_from = Path(args.cases_from)
        if cases_from.resolve() == Path(args.out).resolve():
            raise InputError("must differ from -o (the earlier run's reports and scores are kept)", "--cases-from")
        try:
            stored_cases(cases_from)
        except ValueError as exc:
            raise InputError(str(exc), "--cases-from") from None
    # written in place (the labels name their cases' paths), the previous run put back if this one fails
    staged = OutputFolder(args.out, command="diagnose-benchmark", in_place=True)
    sc = run_benchmark(args.cases, args.seed, Path(args.out), scn, args.scheduler, args.duration_h * 3600.0,
                       args.rate_hz, args.null_runs or N_NULL, args.workers, progress=True, mix=mix,
                       cases_from=cases_from)
    staged.commit()
    slim = {k: v for k, v in sc.items() if k != "rows"}
    if args.json:
        sys.stdout.write(json.dumps(slim, default=float) + "\n")
    else:
        from ..validation.scores_report import format_scores
        sys.stderr.write(format_scores(sc) + f"\nscores: {Path(args.out) / 'scores.json'} (per-case rows), "
                                             f"{Path(args.out) / 'scores.md'}\n")
    return 0
