"""The tuning report: robust gains beside the pole-zero rule and the scenario's gains, checked in simulation."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..device import Device
from .linear_loop import analyze_loop, build_loop, diagram_at, pole_zero_rule
from .robust import RobustResult, RobustSpec, tune_robust
from .verify import check_startup, check_step

#: Temperatures of the report table and of the simulation checks.
CHECK_TEMPERATURES_C = (-40.0, 25.0, 85.0)


@dataclass
class TuneReport:
    """Everything ``fmvmg tune`` prints, writes and plots.

    Attributes
    ----------
    gains : dict
        Label (``robust`` or ``given``, ``pole_zero``, ``current``) -> (Kp, Ki).
    tuned : str
        The label of the gains the report is about (``robust`` or ``given``).
    robust : RobustResult or None
    metrics : dict
        Label -> list of LoopMetrics at :attr:`temperatures_C`.
    steps : dict
        Label -> list of StepCheck (empty without simulation).
    startups : list of StartupCheck
        Start-up checks of the tuned gains.
    temperatures_C : list of float
    """

    gains: dict
    tuned: str
    robust: RobustResult | None
    metrics: dict
    steps: dict = field(default_factory=dict)
    startups: list = field(default_factory=list)
    temperatures_C: list = field(default_factory=list)

    def loops(self, device: Device) -> dict:
        """python-control loops of every gain set at every temperature (for the Bode plot).

        Parameters
        ----------
        device : Device

        Returns
        -------
        dict
        """
        out = {}
        for label, (kp, ki) in self.gains.items():
            for T in self.temperatures_C:
                out[f"{label} {T:g} C"] = build_loop(diagram_at(device, T), kp, ki)
        return out

    def rows(self, label: str) -> list[dict]:
        """Per-temperature rows of one gain set (the JSON ``temperatures`` list).

        Parameters
        ----------
        label : str

        Returns
        -------
        list of dict
        """
        steps = {c.temperature_C: c for c in self.steps.get(label, [])}
        starts = {c.temperature_C: c for c in self.startups} if label == self.tuned else {}
        out = []
        for m in self.metrics[label]:
            c = steps.get(m.temperature_C)
            s = starts.get(m.temperature_C)
            out.append(dict(
                temperature_C=m.temperature_C, phase_margin_deg=m.phase_margin_deg, gain_margin_db=m.gain_margin_db,
                crossover_Hz=m.crossover_rad_s / (2 * math.pi), bandwidth_Hz=m.bandwidth_Hz,
                settling_predicted_s=m.settling_time_s, overshoot_predicted=m.overshoot_pct,
                settling_simulated_s=c.settling_simulated_s if c else None,
                overshoot_simulated=c.overshoot_simulated_pct if c else None,
                step_rms_difference=c.rms_difference if c else None, step_check_ok=c.ok if c else None,
                u_peak_V=m.u_peak_V, u0_V=m.u0_V, tau_d_s=m.params.tau_d_s, q_drive=m.params.q_drive,
                startup=s.as_dict() if s else None))
        return out

    def as_dict(self) -> dict:
        """The JSON report (``tune.json``; ``--json`` prints it).

        Returns
        -------
        dict
            ``kp``, ``ki`` (the tuned gains), ``temperatures`` (rows of the tuned gains),
            ``gains`` (every gain set with its rows), ``robust`` (the NLP and its
            python-control check over all scenarios).
        """
        kp, ki = self.gains[self.tuned]
        return dict(kp=kp, ki=ki, tuned=self.tuned, temperatures=self.rows(self.tuned),
                    gains={label: dict(kp=g[0], ki=g[1], temperatures=self.rows(label))
                           for label, g in self.gains.items()},
                    robust=self.robust.as_dict() if self.robust else None)


def build_report(device: Device, temperatures_C=CHECK_TEMPERATURES_C, spec: RobustSpec | None = None,
                 given: tuple | None = None, simulate: bool = True, log=None) -> TuneReport:
    """Robust (or given) gains, the pole-zero rule and the device's gains at each temperature.

    Parameters
    ----------
    device : Device
        The device with the scenario's overrides (its PI gains are the "current" ones).
    temperatures_C : sequence of float, optional
    spec : RobustSpec, optional
    given : tuple of float, optional
        (Kp, Ki) to check instead of running the robust optimisation.
    simulate : bool, optional
        Run the carrier-engine checks (steps for every gain set, start-up for the tuned gains).
    log : callable, optional

    Returns
    -------
    TuneReport
    """
    log = log or (lambda m: None)
    pi = device.values["circuit"]["pi"]
    gains = {}
    robust = None
    if given is not None:
        gains["given"] = (float(given[0]), float(given[1]))
        tuned = "given"
    else:
        robust = tune_robust(device, spec, log=log)
        gains["robust"] = (robust.kp, robust.ki_per_s)
        tuned = "robust"
    gains["pole_zero"] = pole_zero_rule(device.reference_diagram)
    gains["current"] = (float(pi["kp"]), float(pi["ki_per_s"]))
    temps = [float(t) for t in temperatures_C]
    metrics = {label: [analyze_loop(diagram_at(device, T), kp, ki) for T in temps] for label, (kp, ki) in gains.items()}
    steps, starts = {}, []
    if simulate:
        for label, (kp, ki) in gains.items():
            steps[label] = []
            for T in temps:
                c = check_step(device, T, kp, ki)
                log(f"step check {label} at {T:g} C: settling {c.settling_simulated_s * 1e3:.2f} ms simulated, "
                    f"{c.settling_predicted_s * 1e3:.2f} ms predicted; overshoot {c.overshoot_simulated_pct:.2f} % / "
                    f"{c.overshoot_predicted_pct:.2f} %")
                steps[label].append(c)
        kp, ki = gains[tuned]
        for T in temps:
            s = check_startup(device, T, kp, ki)
            log(f"start-up check at {T:g} C: settled (2 %) at {s.settling_simulated_s * 1e3:.1f} ms simulated, "
                f"{s.settling_predicted_s * 1e3:.1f} ms averaged model")
            starts.append(s)
    return TuneReport(gains, tuned, robust, metrics, steps, starts, temps)


def format_table(report: TuneReport) -> str:
    """The human-readable table of gains, margins and predicted/simulated step metrics.

    Parameters
    ----------
    report : TuneReport

    Returns
    -------
    str
    """
    def f(v, scale=1.0, fmt="{:.2f}"):
        return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v * scale)

    head = (f"{'gains':<10} {'Kp':>8} {'Ki 1/s':>8} {'T C':>6} {'PM deg':>7} {'GM dB':>6} {'fc Hz':>6} "
            f"{'ts pred ms':>10} {'ts sim ms':>9} {'OS pred %':>9} {'OS sim %':>8} {'u_pk V':>7}")
    lines = [head, "-" * len(head)]
    for label, (kp, ki) in report.gains.items():
        for r in report.rows(label):
            lines.append(
                f"{label:<10} {kp:>8.4g} {ki:>8.4g} {r['temperature_C']:>6g} {f(r['phase_margin_deg']):>7} "
                f"{f(r['gain_margin_db']):>6} {f(r['crossover_Hz'], fmt='{:.1f}'):>6} "
                f"{f(r['settling_predicted_s'], 1e3):>10} {f(r['settling_simulated_s'], 1e3):>9} "
                f"{f(r['overshoot_predicted']):>9} {f(r['overshoot_simulated']):>8} {f(r['u_peak_V']):>7}")
    if report.robust is not None:
        w = report.robust.worst
        sp = report.robust.spec
        lines.append("")
        lines.append(
            f"robust: worst case over {len(sp.temperatures_C)} temperatures x Q_d factors {list(sp.q_factors)}: "
            f"settling {w['settling_time_s'] * 1e3:.2f} ms, PM {w['phase_margin_deg']:.1f} deg, "
            f"GM {w['gain_margin_db']:.1f} dB, overshoot {w['overshoot_pct']:.2f} %, u peak {w['u_peak_V']:.2f} V "
            f"(IPOPT {report.robust.solver_status}, {report.robust.solver_iterations} iterations, "
            f"{report.robust.wall_time_s:.0f} s)")
    if report.startups:
        lines.append("")
        for s in report.startups:
            lines.append(
                f"start-up {report.tuned} at {s.temperature_C:g} C: 2 % settling "
                f"{f(s.settling_simulated_s, 1e3, '{:.1f}')} ms "
                f"simulated / {f(s.settling_predicted_s, 1e3, '{:.1f}')} ms averaged model; PI at u_max until "
                f"{s.saturated_until_simulated_s * 1e3:.1f} ms / {s.saturated_until_predicted_s * 1e3:.1f} ms")
    return "\n".join(lines)
