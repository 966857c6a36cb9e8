"""Check tuned gains in simulation: a 10 % Vref step and the start-up, on the carrier engine.

The scenarios come from the templates ``scenarios/tune_step.toml`` and
``scenarios/tune_startup.toml`` loaded with ``--set``-style overrides (temperature, PI
gains, duration); the device is then replaced by the caller's (so a user's scenario
overrides of the circuit carry over). The step starts from the loop's averaged steady
state (``[initial] state = "steady"``) and is measured with
:func:`fmvmg_sim.tuning.linear_loop.step_metrics`, the definition ``control.step_info``
uses for the linear prediction.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..device import Device
from ..scenario import Scenario, load_scenario
from .linear_loop import LoopMetrics, analyze_loop, diagram_at, step_metrics
from .startup import averaged_startup
from ..paths import scenarios_dir

SCENARIOS_DIR = scenarios_dir()
#: Template of the set-point step check.
STEP_TEMPLATE = SCENARIOS_DIR / "tune_step.toml"
#: Template of the start-up check.
STARTUP_TEMPLATE = SCENARIOS_DIR / "tune_startup.toml"
#: Acceptance: relative settling-time error and absolute overshoot error (percentage points).
SETTLING_REL_TOL = 0.15
OVERSHOOT_ABS_TOL_PCT = 2.0


def make_scenario(template: str | Path, device: Device, temperature_C: float, kp: float, ki_per_s: float,
                  overrides: list[str] | None = None, fidelity: str | None = None) -> Scenario:
    """A check scenario: the template at ``temperature_C`` with the gains, on ``device``.

    Parameters
    ----------
    template : str or Path
        Template TOML.
    device : Device
        Device (with any circuit overrides) to simulate.
    temperature_C : float
    kp, ki_per_s : float
    overrides : list of str, optional
        More ``KEY=VALUE`` overrides of the template.
    fidelity : str, optional
        Engine (default: the template's, carrier).

    Returns
    -------
    Scenario
    """
    sets = [f"temperature.start_C={float(temperature_C)!r}"] + list(overrides or [])
    scn = load_scenario(template, sets, fidelity=fidelity)
    dev = device.with_overrides({"circuit": {"pi": {"kp": float(kp), "ki_per_s": float(ki_per_s)}}},
                                f"{template} (tuned gains)")
    return dataclasses.replace(scn, device=dev)


def _run(scn: Scenario):
    if scn.fidelity() == "carrier":
        from ..carrier.engine import run_carrier
        return run_carrier(scn, progress=False)
    from ..envelope.engine import run_envelope
    return run_envelope(scn, progress=False)


@dataclass
class StepCheck:
    """Predicted against simulated step metrics at one temperature.

    Attributes
    ----------
    temperature_C, kp, ki_per_s : float
    predicted : LoopMetrics
    settling_simulated_s, overshoot_simulated_pct : float
    settling_predicted_s, overshoot_predicted_pct : float
    t_s : ndarray
        Time from the step.
    r_simulated_unit, r_predicted_unit : ndarray
        Normalised responses (0 before, 1 at the new set-point); the prediction sampled
        at ``t_s``.
    engine : str
    wall_time_s : float
    """

    temperature_C: float
    kp: float
    ki_per_s: float
    predicted: LoopMetrics
    settling_simulated_s: float
    overshoot_simulated_pct: float
    t_s: np.ndarray = field(repr=False)
    r_simulated_unit: np.ndarray = field(repr=False)
    r_predicted_unit: np.ndarray = field(repr=False)
    engine: str = "carrier"
    wall_time_s: float = 0.0

    @property
    def settling_predicted_s(self) -> float:
        """Linear-model settling time."""
        return self.predicted.settling_time_s

    @property
    def overshoot_predicted_pct(self) -> float:
        """Linear-model overshoot (percent)."""
        return self.predicted.overshoot_pct

    @property
    def settling_error_rel(self) -> float:
        """(simulated - predicted) / predicted settling time."""
        return (self.settling_simulated_s - self.settling_predicted_s) / self.settling_predicted_s

    @property
    def rms_difference(self) -> float:
        """RMS of simulated minus predicted normalised response (fraction of the step).

        Returns
        -------
        float
        """
        return float(np.sqrt(np.mean((self.r_simulated_unit - self.r_predicted_unit) ** 2)))

    @property
    def ok(self) -> bool:
        """Settling within :data:`SETTLING_REL_TOL` and overshoot within :data:`OVERSHOOT_ABS_TOL_PCT`."""
        return bool(abs(self.settling_error_rel) <= SETTLING_REL_TOL
                    and abs(self.overshoot_simulated_pct - self.overshoot_predicted_pct) <= OVERSHOOT_ABS_TOL_PCT)

    def as_dict(self) -> dict:
        """JSON-ready dict.

        Returns
        -------
        dict
        """
        return dict(temperature_C=self.temperature_C, kp=self.kp, ki_per_s=self.ki_per_s, engine=self.engine,
                    settling_predicted_s=self.settling_predicted_s, settling_simulated_s=self.settling_simulated_s,
                    settling_error_rel=self.settling_error_rel, overshoot_predicted=self.overshoot_predicted_pct,
                    overshoot_simulated=self.overshoot_simulated_pct, rms_difference=self.rms_difference,
                    ok=self.ok, wall_time_s=self.wall_time_s)


def step_duration_s(predicted: LoopMetrics, hold_s: float = 0.01) -> float:
    """Simulated time for a step check: the hold, then 4 predicted settling times (at least 40 ms).

    Parameters
    ----------
    predicted : LoopMetrics
    hold_s : float, optional

    Returns
    -------
    float
    """
    ts = predicted.settling_time_s if np.isfinite(predicted.settling_time_s) else 0.5
    return float(hold_s + np.clip(4 * ts, 0.04, 2.0))


def check_step(device: Device, temperature_C: float, kp: float, ki_per_s: float, step_factor: float = 1.1,
               hold_s: float = 0.01, duration_s: float | None = None, fidelity: str | None = None,
               template: str | Path = STEP_TEMPLATE) -> StepCheck:
    """Simulate a set-point step from the steady state and compare it with the linearised loop.

    Parameters
    ----------
    device : Device
    temperature_C : float
    kp, ki_per_s : float
    step_factor : float, optional
        New set-point as a multiple of Vref (1.1 = a 10 % step).
    hold_s : float, optional
        Time on the steady state before the step.
    duration_s : float, optional
        Simulated time (default :func:`step_duration_s`).
    fidelity : str, optional
        'carrier' (default) or 'envelope'.
    template : str or Path, optional

    Returns
    -------
    StepCheck
    """
    from ..runner import vref_profile_V
    dg = diagram_at(device, temperature_C)
    pred = analyze_loop(dg, kp, ki_per_s, step_fraction=step_factor - 1.0)
    dur = duration_s or step_duration_s(pred, hold_s)
    scn = make_scenario(template, device, temperature_C, kp, ki_per_s, overrides=[
        f"scenario.duration_s={dur!r}",
        f"vref.segments=[{{hold_s = {hold_s!r}}}, {{step_to_factor = {float(step_factor)!r}}}]"],
        fidelity=fidelity)
    res = _run(scn)
    t = res.time_s
    dt = np.diff(t, prepend=0.0)
    t_mid = t - dt / 2                           # the engines hold each sample's inputs over its interval
    f = np.asarray(scn.vref_factor(t_mid), dtype=float)
    k = int(np.argmax(np.abs(f - f[0]) > 0.5 * abs(step_factor - 1.0)))

    t_step = t[k] - dt[k]                        # start of the first interval with the new set-point
    vref = vref_profile_V(scn, t_mid, res["temperature_C"])
    v0, v1 = float(vref[k - 1]), float(vref[-1])
    tt = t[k:] - t_step
    r = res["drive_amplitude_V"][k:]
    sim = step_metrics(np.concatenate([[0.0], tt]), np.concatenate([[v0], r]), v0, v1)
    r_unit = (r - v0) / (v1 - v0)
    r_pred = np.interp(tt - dt[k:] / 2, pred.t_s, pred.r_unit)  # a record's sample is the mean over its interval
    return StepCheck(temperature_C=float(temperature_C), kp=float(kp), ki_per_s=float(ki_per_s), predicted=pred,
                     settling_simulated_s=sim["settling_time_s"], overshoot_simulated_pct=sim["overshoot_pct"],
                     t_s=tt, r_simulated_unit=r_unit, r_predicted_unit=r_pred, engine=res.info.get("engine", "?"),
                     wall_time_s=float(res.info.get("wall_time_s", float("nan"))))


@dataclass
class StartupCheck:
    """Carrier-engine start-up against the averaged large-signal model at one temperature.

    Attributes
    ----------
    temperature_C, kp, ki_per_s : float
    settling_simulated_s, settling_predicted_s : float
        2 % settling of the amplitude estimate to Vref, from t = 0.
    overshoot_simulated_pct, overshoot_predicted_pct : float
    saturated_until_simulated_s, saturated_until_predicted_s : float
        Last time the PI output sits at u_max.
    t_s, r_simulated_V, r_predicted_V, u_simulated_V, u_predicted_V : ndarray
    vref_V : float
    wall_time_s : float
    """

    temperature_C: float
    kp: float
    ki_per_s: float
    settling_simulated_s: float
    settling_predicted_s: float
    overshoot_simulated_pct: float
    overshoot_predicted_pct: float
    saturated_until_simulated_s: float
    saturated_until_predicted_s: float
    t_s: np.ndarray = field(repr=False)
    r_simulated_V: np.ndarray = field(repr=False)
    r_predicted_V: np.ndarray = field(repr=False)
    u_simulated_V: np.ndarray = field(repr=False)
    u_predicted_V: np.ndarray = field(repr=False)
    vref_V: float = 0.0
    wall_time_s: float = 0.0

    def as_dict(self) -> dict:
        """JSON-ready dict.

        Returns
        -------
        dict
        """
        return {k: getattr(self, k) for k in (
            "temperature_C", "kp", "ki_per_s", "settling_simulated_s", "settling_predicted_s",
            "overshoot_simulated_pct", "overshoot_predicted_pct", "saturated_until_simulated_s",
            "saturated_until_predicted_s", "vref_V", "wall_time_s")}


def _saturated_until(t, u, u_max):
    on = np.flatnonzero(u >= u_max * (1 - 1e-9))
    return float(t[on[-1]]) if on.size else 0.0


def check_startup(device: Device, temperature_C: float, kp: float, ki_per_s: float, duration_s: float = 0.2,
                  template: str | Path = STARTUP_TEMPLATE) -> StartupCheck:
    """Simulate the start-up from rest on the carrier engine and on the averaged large-signal model.

    Parameters
    ----------
    device : Device
    temperature_C : float
    kp, ki_per_s : float
    duration_s : float, optional
    template : str or Path, optional

    Returns
    -------
    StartupCheck
    """
    scn = make_scenario(template, device, temperature_C, kp, ki_per_s,
                        overrides=[f"scenario.duration_s={float(duration_s)!r}"])
    res = _run(scn)
    t = res.time_s
    dg = diagram_at(scn.device, temperature_C)
    a0 = scn.settings["initial"]["drive_displacement_m"]
    avg = averaged_startup(dg, kp, ki_per_s, duration_s, amplitude0_m=a0)
    r_pred = np.interp(t, avg["t_s"], avg["r_V"])
    u_pred = np.interp(t, avg["t_s"], avg["u_V"])
    v = dg.vref_V
    r_sim = res["drive_amplitude_V"]
    sim = step_metrics(np.concatenate([[0.0], t]), np.concatenate([[0.0], r_sim]), 0.0, v)
    prd = step_metrics(np.concatenate([[0.0], avg["t_s"]]), np.concatenate([[0.0], avg["r_V"]]), 0.0, v)
    u_max = dg.pi.u_max_V
    return StartupCheck(
        temperature_C=float(temperature_C), kp=float(kp), ki_per_s=float(ki_per_s),
        settling_simulated_s=sim["settling_time_s"], settling_predicted_s=prd["settling_time_s"],
        overshoot_simulated_pct=sim["overshoot_pct"], overshoot_predicted_pct=prd["overshoot_pct"],
        saturated_until_simulated_s=_saturated_until(t, res["agc_effort_V"], u_max),
        saturated_until_predicted_s=_saturated_until(avg["t_s"], avg["u_V"], u_max),
        t_s=t, r_simulated_V=r_sim, r_predicted_V=r_pred, u_simulated_V=res["agc_effort_V"], u_predicted_V=u_pred,
        vref_V=v, wall_time_s=float(res.info.get("wall_time_s", float("nan"))))
