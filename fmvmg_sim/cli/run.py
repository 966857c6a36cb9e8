"""``fmvmg run SCENARIO.toml``: simulate, write record.csv, summary.json and plots."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..jsonout import strict
from .options import add_json, add_no_plots, add_no_progress, add_output, add_overrides, output_dir, progress


def register(sub) -> None:
    """Add the ``run`` sub-command to ``sub`` (an ``argparse._SubParsersAction``)."""
    p = sub.add_parser("run", help="simulate a scenario", description=(
        "Simulate a scenario; writes DIR/record.csv (docs/formats.md section 2), DIR/summary.json and PNG plots."))
    p.add_argument("scenario", help="scenario TOML file")
    add_output(p, None, "output folder (default: out/<scenario name>)")
    p.add_argument("--seed", type=int, default=None, help="random seed (overrides scenario.seed)")
    p.add_argument("--fidelity", choices=("carrier", "envelope", "auto"), default=None,
                   help="engine: carrier (every drive cycle) or envelope (averaged); auto picks envelope above 60 s")
    add_overrides(p)
    add_json(p)
    add_no_plots(p)
    add_no_progress(p)
    p.set_defaults(func=main)


def main(args) -> int:
    """Run the sub-command with the parsed ``args``; returns the exit code."""
    from ..output import output_folder
    from ..record import atomic_write_text, write_record
    from ..runner import check_fits_in_memory, record_size, run_scenario, vref_profile_V
    from ..scenario import load_scenario

    scn = load_scenario(args.scenario, args.overrides, seed=args.seed, fidelity=args.fidelity)
    out = output_dir(args, Path("out") / scn.name)
    check_fits_in_memory(scn)
    with output_folder(out, expect_bytes=record_size(scn)["csv_bytes"], command="run") as tmp:
        res, summary = run_scenario(scn, progress=progress(args))
        write_record(tmp / "record.csv", res.to_record())
        atomic_write_text(tmp / "summary.json", json.dumps(strict(summary), indent=2) + "\n")
        if not args.no_plots:
            from ..plots import drive_loop_title, plot_channels, plot_startup
            title = drive_loop_title(scn.name, scn.settings["initial"]["state"], scn.duration_s)
            plot_startup(res, vref_profile_V(scn, res.time_s, res["temperature_C"]), tmp / "startup.png", title)
            plot_channels(res, tmp / "channels.png")
            if res.info.get("engine") == "envelope" or scn.duration_s > 60:
                from ..plots_long import plot_long_run
                plot_long_run(res, tmp)
    for m in summary["messages"]:
        sys.stderr.write(f"fmvmg: {summary['status']}: {m}\n")
    if args.json:
        sys.stdout.write(json.dumps(strict(summary)) + "\n")
    else:
        s = summary
        sys.stderr.write(
            f"fmvmg: {scn.name}: {s['status']}; drive {s['drive_amplitude_V']:.5g} V (set-point "
            f"{s['drive_amplitude_setpoint_V']:.5g} V) at {s['drive_frequency_Hz']:.3f} Hz, AGC effort "
            f"{s['agc_effort_V']:.4g} V, settled at {s['settling_time_s']:.3g} s; wrote {out}/record.csv "
            f"({s['simulated_time_s']:.3g} s simulated in {s['wall_time_s']:.2f} s)\n")
    return 0
