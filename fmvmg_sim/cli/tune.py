"""``fmvmg tune [SCENARIO.toml]``: PI gains of the drive amplitude loop, robust over temperature, checked in simulation.

Thin front end of :mod:`fmvmg_sim.tuning.report` (robust gains, table, plots) and
:mod:`fmvmg_sim.tuning.sweep` (``--sweep`` on Dask). Bad arguments raise
:class:`fmvmg_sim.errors.InputError` naming the option (exit code 2).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..jsonout import strict
from ..paths import scenarios_dir
from .options import add_json, add_no_plots, add_no_progress, add_output, add_overrides

DEFAULT_SCENARIO = scenarios_dir() / "startup.toml"
#: The PLL's target crossover when --bandwidth-Hz is not given (Hz).
PLL_BANDWIDTH_HZ = 30.0


def register(sub) -> None:
    """Add the ``tune`` sub-command to ``sub`` (an ``argparse._SubParsersAction``)."""
    p = sub.add_parser("tune", help="PI gains of the drive amplitude loop (robust over temperature)", description=(
        "Linearise the AGC loop of the scenario's device at each temperature, choose PI gains that minimise the "
        "worst-case settling time over -40..85 C and a Q_d tolerance (CasADi/IPOPT) subject to phase margin, gain "
        "margin, overshoot and PI output limits, and check them with the carrier engine (10 %% Vref step and "
        "start-up). Prints a table (stdout), writes DIR/tune.json and Bode/step/start-up plots. With --sweep: a "
        "grid of gains and temperatures on Dask instead (DIR/sweep.csv, sweep.json, sweep_heatmap.png)."))
    p.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO),
                   help="scenario TOML whose device (and circuit overrides) to tune (default: scenarios/startup.toml)")
    add_output(p, "out/tune")
    add_overrides(p, "device.mechanics.q_drive=3e4")
    add_json(p, "the report")
    p.add_argument("--no-sim", action="store_true", help="skip the carrier-engine checks (linear model only)")
    add_no_plots(p)
    p.add_argument("--gains", nargs=2, type=float, metavar=("KP", "KI"), default=None,
                   help="check these gains instead of running the robust optimisation")
    p.add_argument("--temperatures", nargs="+", type=float, metavar="C", default=None,
                   help="temperatures of the table and the simulation checks (default -40 25 85)")
    p.add_argument("--grid-points", type=int, default=6,
                   help="temperatures in the robust problem's grid over -40..85 C (default 6)")
    p.add_argument("--q-tolerance", type=float, default=0.2, help="relative Q_d tolerance (default 0.2 = +-20 %%)")
    g = p.add_argument_group("gain sweep (Dask)")
    g.add_argument("--sweep", action="store_true", help="evaluate a grid of Kp, Ki and temperatures on Dask")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of an existing Dask scheduler (default: start a LocalCluster)")
    g.add_argument("--workers", type=int, default=2, help="LocalCluster workers, 1 thread each (default 2)")
    g.add_argument("--sweep-sim", action="store_true", help="add a short carrier-engine step check to every task")
    g.add_argument("--kp-grid", nargs=3, type=float, metavar=("LO", "HI", "N"), default=[20.0, 200.0, 10],
                   help="Kp values: N points from LO to HI (default 20 200 10)")
    g.add_argument("--ki-grid", nargs=3, type=float, metavar=("LO", "HI", "N"), default=[100.0, 1500.0, 8],
                   help="Ki values (1/s): N points from LO to HI (default 100 1500 8)")
    p.add_argument("--loop", choices=("agc", "rebalance", "pll"), default="agc",
                   help="the loop to tune: the drive amplitude loop (default), the force-to-rebalance sense loop "
                        "(its margins over -40..85 C and Q_s +- --q-tolerance, checked with carrier-engine rate steps) "
                        "or the PLL drive's phase loop (the scenario's device with [circuit.drive] topology = \"pll\")")
    p.add_argument("--bandwidth-Hz", type=float, default=None,
                   help="--loop rebalance: design the gains for this integral pole (default: check the device's); "
                        "--loop pll: the target crossover (default 30 Hz)")
    p.add_argument("--phase-margin-deg", type=float, default=60.0, help="--loop pll: target phase margin (default 60)")
    add_no_progress(p)
    p.set_defaults(func=main)


def _grid(values, name):
    import numpy as np
    from ..errors import InputError
    lo, hi, n = values
    if not (n >= 1 and float(n).is_integer()):
        raise InputError(f"N must be a positive integer, got {n:g}", name)
    if not (0 <= lo <= hi) or (n > 1 and lo == hi):
        raise InputError(f"expected 0 <= LO < HI, got LO={lo:g} HI={hi:g}", name)
    return [float(v) for v in np.linspace(lo, hi, int(n))]


def _check_args(args):
    from ..errors import InputError
    if args.gains is not None and (not args.gains[0] > 0 or not args.gains[1] >= 0):
        raise InputError(f"expected Kp > 0 and Ki >= 0, got {args.gains}", "--gains")
    if not 0 <= args.q_tolerance < 0.9:
        raise InputError(f"expected 0 <= tolerance < 0.9, got {args.q_tolerance:g}", "--q-tolerance")
    if args.grid_points < 1:
        raise InputError(f"expected at least 1, got {args.grid_points}", "--grid-points")
    if args.workers < 1:
        raise InputError(f"expected at least 1, got {args.workers}", "--workers")
    for t in args.temperatures or []:
        if not -100.0 <= t <= 200.0:
            raise InputError(f"temperature {t:g} C outside -100..200 C", "--temperatures")
    if args.bandwidth_Hz is not None and not args.bandwidth_Hz > 0:
        raise InputError(f"expected a positive bandwidth, got {args.bandwidth_Hz:g}", "--bandwidth-Hz")
    if not 0 < args.phase_margin_deg < 90:
        raise InputError(f"expected 0 < margin < 90 deg, got {args.phase_margin_deg:g}", "--phase-margin-deg")


def main(args) -> int:
    """Run the sub-command with the parsed ``args``; returns the exit code."""
    import numpy as np

    from ..output import output_folder
    from ..record import atomic_write_text
    from ..scenario import load_scenario
    from ..tuning.report import CHECK_TEMPERATURES_C, build_report, format_table
    from ..tuning.robust import RobustSpec

    _check_args(args)
    log = (lambda m: None) if args.no_progress else (lambda m: sys.stderr.write(f"fmvmg tune: {m}\n"))
    scn = load_scenario(args.scenario, args.overrides)
    device = scn.device
    out = Path(args.out)
    temps = args.temperatures or list(CHECK_TEMPERATURES_C)
    if args.loop == "rebalance":
        return _rebalance(args, device, out, temps, log)
    if args.sweep:
        return _sweep(args, device, out, temps, log)
    if args.loop == "pll":
        return _tune_pll(args, device, out, temps, log)
    qt = args.q_tolerance
    spec = RobustSpec(temperatures_C=tuple(np.linspace(-40.0, 85.0, args.grid_points)),
                      q_factors=(1.0 - qt, 1.0, 1.0 + qt) if qt > 0 else (1.0,))
    with output_folder(out, command="tune") as tmp:
        report = build_report(device, temps, spec, given=args.gains, simulate=not args.no_sim, log=log)
        data = strict(report.as_dict())
        data["scenario"] = str(args.scenario)
        atomic_write_text(tmp / "tune.json", json.dumps(data, indent=2) + "\n")
        if not args.no_plots:
            from ..tuning.plots import plot_bode, plot_startups, plot_steps
            plot_bode(report.loops(device), tmp / "bode.png")
            tuned = report.tuned
            if report.steps:
                plot_steps(report.steps[tuned], tmp / "step.png")
            else:
                plot_steps([], tmp / "step.png", predicted_only=report.metrics[tuned])
            if report.startups:
                plot_startups(report.startups, tmp / "startup.png")
    if args.json:
        sys.stdout.write(json.dumps(data) + "\n")
    else:
        sys.stdout.write(format_table(report) + "\n")
        sys.stdout.write(f"wrote {out}/tune.json" + ("" if args.no_plots else " and plots") + "\n")
    return 0


def _rebalance(args, device, out, temps, log) -> int:
    import numpy as np

    from ..output import output_folder
    from ..record import atomic_write_text
    from ..tuning.rebalance import format_rebalance_table, rebalance_report
    from ..errors import InputError
    if args.bandwidth_Hz is not None and not args.bandwidth_Hz > 0:
        raise InputError(f"expected > 0, got {args.bandwidth_Hz:g}", "--bandwidth-Hz")
    qt = args.q_tolerance
    report = rebalance_report(device, temps, list(np.linspace(-40.0, 85.0, args.grid_points)),
                              (1.0 - qt, 1.0, 1.0 + qt) if qt > 0 else (1.0,), args.bandwidth_Hz,
                              simulate=not args.no_sim, log=log)
    data = strict(report)
    data["scenario"] = str(args.scenario)
    with output_folder(out, command="tune") as tmp:
        atomic_write_text(tmp / "tune.json", json.dumps(data, indent=2) + "\n")
    if args.json:
        sys.stdout.write(json.dumps(data) + "\n")
    else:
        sys.stdout.write(format_rebalance_table(report) + "\n")
        sys.stdout.write(f"wrote {out}/tune.json\n")
    return 0


def _sweep(args, device, out, temps, log) -> int:
    from ..output import output_folder
    from ..record import atomic_write_text
    from ..tuning.sweep import run_sweep
    kps = _grid(args.kp_grid, "--kp-grid")
    kis = _grid(args.ki_grid, "--ki-grid")
    with output_folder(out, command="tune --sweep") as tmp:
        res = run_sweep(device, kps, kis, temps, simulate=args.sweep_sim, scheduler=args.scheduler,
                        n_workers=args.workers, log=log)
        atomic_write_text(tmp / "sweep.csv", res.to_csv())
        data = strict(res.as_dict())
        atomic_write_text(tmp / "sweep.json", json.dumps(data, indent=2) + "\n")
        if not args.no_plots:
            from ..tuning.linear_loop import pole_zero_rule
            from ..tuning.plots import plot_sweep_heatmap
            pi = device.values["circuit"]["pi"]
            marks = {"pole-zero rule": pole_zero_rule(device.reference_diagram),
                     "current": (pi["kp"], pi["ki_per_s"])}
            if args.gains:
                marks["given"] = tuple(args.gains)
            plot_sweep_heatmap(res, tmp / "sweep_heatmap.png", marks)
    best = res.best()
    if args.json:
        sys.stdout.write(json.dumps(data) + "\n")
    else:
        sys.stdout.write(f"sweep: {len(res.rows)} points on {res.cluster}; best feasible: "
                         + (f"Kp={best['kp']:.4g} Ki={best['ki_per_s']:.4g}, worst-case settling "
                            f"{best['worst_settling_time_s'] * 1e3:.2f} ms" if best else "none") + "\n")
        sys.stdout.write(f"wrote {out}/sweep.csv, sweep.json" + ("" if args.no_plots else ", sweep_heatmap.png") + "\n")
    return 0


def _tune_pll(args, device, out, temps, log) -> int:
    """``--loop pll``: the phase loop's gains, its margins over temperature and Q, checked in the envelope engine."""
    import numpy as np

    from ..errors import InputError
    from ..output import output_folder
    from ..record import atomic_write_text
    from ..tuning.pll import PLL_GRID_C, check_pll_gains, design_pll_gains

    if device.drive_topology != "pll":
        device = device.with_overrides({"circuit": {"drive": {"topology": "pll"}}}, str(args.scenario))
    if args.bandwidth_Hz is None:
        args.bandwidth_Hz = PLL_BANDWIDTH_HZ
    qt = args.q_tolerance
    qf = (1.0 - qt, 1.0, 1.0 + qt) if qt > 0 else (1.0,)
    if args.gains:
        kp, ki = args.gains
        design = design_pll_gains(device, args.bandwidth_Hz, args.phase_margin_deg, PLL_GRID_C, qf, log)
        from ..tuning.pll import PLLDesign, loop_transfer, margins, _pll_at
        rows = [dict(temperature_C=r["temperature_C"], q_factor=r["q_factor"],
                     **margins(loop_transfer(_pll_at(device, r["temperature_C"], r["q_factor"]), kp, ki)))
                for r in design.rows]
        design = PLLDesign(kp, ki, args.bandwidth_Hz, args.phase_margin_deg, rows)
    else:
        try:
            design = design_pll_gains(device, args.bandwidth_Hz, args.phase_margin_deg, PLL_GRID_C, qf, log)
        except ValueError as err:
            raise InputError(str(err), "--phase-margin-deg") from None
    checks = []
    if not args.no_sim:
        for T in temps:
            log(f"checking the gains in the envelope engine at {T:g} C")
            c = check_pll_gains(device, design.kp, design.ki_per_s, T)
            checks.append(dict(temperature_C=float(T), **c))
    data = {"loop": "pll", "kp": design.kp, "ki_per_s": design.ki_per_s,
            "target_bandwidth_Hz": design.target_bandwidth_Hz,
            "target_phase_margin_deg": design.target_phase_margin_deg, "worst": design.worst(), "grid": design.rows,
            "checks": [{k: v for k, v in c.items() if not isinstance(v, np.ndarray)} for c in checks],
            "scenario": str(args.scenario)}
    with output_folder(out, command="tune --loop pll") as tmp:
        atomic_write_text(tmp / "tune_pll.json", json.dumps(strict(data), indent=2) + "\n")
        if checks and not args.no_plots:
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
            fig, ax = plt.subplots(figsize=(6, 4))
            for c in checks:
                line, = ax.plot(1e3 * c["t_s"], c["simulated_Hz"], label=f"{c['temperature_C']:g} C, envelope engine")
                ax.plot(1e3 * c["t_s"], c["linear_Hz"], "--", color=line.get_color(), label="linear loop")
            ax.set(xlabel="time (ms)", ylabel="oscillator frequency error (Hz)",
                   title=f"PLL: Kp={design.kp:.3g}, Ki={design.ki_per_s:.3g} 1/s")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
            fig.tight_layout()
            fig.savefig(tmp / "pll_check.png", dpi=90)
            plt.close(fig)
    if args.json:
        sys.stdout.write(json.dumps(strict(data)) + "\n")
    else:
        w = design.worst()
        lines = [f"PLL loop filter: Kp = {design.kp:.4g} V/V, Ki = {design.ki_per_s:.4g} 1/s "
                 f"(target {design.target_bandwidth_Hz:g} Hz, {design.target_phase_margin_deg:g} deg)",
                 f"over {len(design.rows)} points (-40..85 C, Q x {', '.join(f'{q:g}' for q in qf)}): crossover "
                 f"{w['crossover_Hz_min']:.2f}..{w['crossover_Hz_max']:.2f} Hz, phase margin >= "
                 f"{w['phase_margin_deg_min']:.1f} deg, gain margin >= {w['gain_margin_dB_min']:.1f} dB"]
        for c in checks:
            lines.append(f"  {c['temperature_C']:6.1f} C: 1 Hz error settles to 2 % in {1e3 * c['settling_simulated_s']:.1f} ms "
                         f"(linear loop {1e3 * c['settling_linear_s']:.1f} ms), largest difference "
                         f"{100 * c['max_difference_rel']:.2f} % of the error")
        sys.stdout.write("\n".join(lines) + f"\nwrote {out}/tune_pll.json\n")
    return 0
