"""``fmvmg population SCENARIO.toml --units N``: units drawn from the tolerances, run on Dask, judged against a spec."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..jsonout import strict
from .options import add_json, add_no_plots, add_no_progress, add_output, add_overrides, output_dir, progress


def register(sub) -> None:
    """Add the ``population`` sub-command to ``sub`` (an ``argparse._SubParsersAction``)."""
    p = sub.add_parser("population", help="population study: yield over the device's tolerances", description=(
        "Draw N units uniformly within the device file's [tolerance] table (unit and law knobs), run each over the "
        "scenario on Dask (a LocalCluster with one worker per core unless --scheduler), and report the figures "
        "of merit's distributions, the yield against a specification and the tolerances that drive the failures. "
        "Writes DIR/population.json, DIR/units.csv and PNG plots (docs/population.md)."))
    p.add_argument("scenario", help="scenario TOML file or shipped name (e.g. population_oven)")
    p.add_argument("--units", type=int, required=True, help="number of units")
    p.add_argument("--spec", default=None, help="specification TOML (default: scenarios/specs/population_oven.toml)")
    p.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler (tcp://host:8786)")
    p.add_argument("--workers", type=int, default=None, help="LocalCluster workers, 1 thread each (default: cores)")
    p.add_argument("--seed", type=int, default=0, help="population seed: every unit's draws and noise (default 0)")
    add_overrides(p, "device.tolerance.demod_phase_mrad=5")
    add_output(p, None, "output folder (default: out/population_<scenario name>)")
    add_json(p, "the report (without per-unit rows)")
    add_no_plots(p)
    add_no_progress(p)
    p.set_defaults(func=main)


def main(args) -> int:
    """Run the sub-command with the parsed ``args``; returns the exit code."""
    from ..errors import InputError
    from ..output import OutputFolder
    from ..population.report import write_report
    from ..population.spec import default_spec_path, load_spec
    from ..population.study import run_population
    from ..scenario import load_scenario
    if args.units < 1:
        raise InputError("needs at least 1 unit", "--units")
    if args.workers is not None and args.workers < 1:
        raise InputError("needs at least 1 worker", "--workers")
    scn = load_scenario(args.scenario, args.overrides)
    spec = load_spec(args.spec if args.spec else default_spec_path())
    out = output_dir(args, Path("out") / f"population_{scn.name}")
    staged = OutputFolder(out, command="population")  # refused now, before the units run, if unwritable
    try:
        pop = run_population(scn, args.units, seed=args.seed, spec=spec, scheduler=args.scheduler,
                             n_workers=args.workers, progress=progress(args))
        rep = write_report(pop, staged.path, plots=not args.no_plots)
    except BaseException:
        staged.discard()
        raise
    staged.commit()
    if args.json:
        sys.stdout.write(json.dumps(strict({k: v for k, v in rep.items() if k != "unit_results"})) + "\n")
    else:
        y = rep["yield"]
        top = ", ".join(d["knob"] for d in rep["drivers"][:3] if d["score"] > 0) or "none"
        sys.stderr.write(f"fmvmg: population: {rep['units']} units of {scn.name}, yield {y['fraction']:.1%} "
                         f"({y['passed']} of {y['units']}, 95 % {y['ci95'][0]:.1%}..{y['ci95'][1]:.1%}) against "
                         f"{spec.name}; top drivers {top}; wrote {out}/population.json ({rep['wall_time_s']:.1f} s)\n")
    return 0
