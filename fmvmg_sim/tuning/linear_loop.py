"""The drive amplitude loop linearised around its averaged steady state (physics brief section 3).

Every number comes from the diagram's blocks at the temperature, none is copied by hand:

* **plant** (amplitude of the drive motion per volt of AGC effort), from the averaged
  model around the operating point of :func:`fmvmg_sim.averaged.steady_state`. Averaging
  ``m x'' + c x' + k x = F`` over a cycle with ``x = A cos(theta)`` gives
  ``A' = -A/tau_d + F_v / (2 m_d omega)``, where ``F_v`` is the force component in phase
  with the velocity and ``tau_d = 2 Q_d / omega_d``. The force is
  ``F = k_comb K_mod u c(t)`` (comb linear coefficient, modulator scale, PI output, carrier),
  so ``F_v = k_comb K_mod u |C| cos(delta)`` with ``|C|`` the carrier fundamental and
  ``delta`` the loop phase error, both from :mod:`fmvmg_sim.averaged`:

  - ``'normalized'`` carrier: ``|C|`` is fixed (``~ Vdac``) whatever the amplitude, so
    ``A' = -A/tau_d + b u`` with ``b = k_comb K_mod |C| cos(delta) / (2 m_d omega)``:
    plant ``b / (s + 1/tau_d)``;
  - ``'pickoff'`` carrier: the carrier is the phase-shifted pickoff itself,
    ``|C| = |C_1| A`` (``C_1`` per metre), so ``A' = (-1/tau_d + b_1 u) A`` with
    ``b_1 = k_comb K_mod |C_1| cos(delta) / (2 m_d omega)``. At the steady state
    ``b_1 u_0 = 1/tau_d``: the ``A`` terms cancel to first order and only
    ``dA' = b_1 A_0 du`` is left, an integrator ``b / s`` with ``b = b_1 A_0`` (the
    same formula as above with ``|C|`` taken at ``A_0``). The damping no longer sets a
    pole, so Q_d drops out of the loop gain (it sets u_0 only).

* **sensor**: the full-wave rectifier's describing gain ``(2/pi) G_r`` times
  ``|H_dx(omega) H_ps(omega)|`` (pickoff, amplifier 1, phase shifter) at the
  oscillation frequency, in V per metre; then the amplitude low-pass
  (``dg.amplitude_lpf.linear_model()``).
* **controller**: ``dg.pi.linear_model()`` (unsaturated face) after the comparator
  ``dg.comparator.linear_model()``.

All systems carry named signals; :func:`build_loop` wires them with
``control.interconnect`` and :func:`analyze_loop` reports margins
(``control.margin``), bandwidth and the step response (``control.step_info``) of the
closed loop ``control.feedback(L, 1)`` from the set-point Vref to the amplitude
estimate r.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field

import control
import numpy as np

from blocks import PIController

from ..averaged import carrier_phasors, steady_state
from ..device import Device, OperatingPoint
from ..diagram import Diagram, build_diagram

#: Settling band of the step metrics (fraction of the step), as in ``control.step_info``.
SETTLING_BAND = 0.02
#: Size of the set-point step the output-limit check uses (fraction of Vref).
STEP_FRACTION = 0.1


def diagram_at(device: Device, temperature_C: float, q_drive_factor: float = 1.0) -> Diagram:
    """The diagram at ``temperature_C`` with the drive Q scaled by ``q_drive_factor`` (tolerance).

    Parameters
    ----------
    device : Device
    temperature_C : float
    q_drive_factor : float, optional
        Multiplier of Q_d(T) from the device's temperature law (1 = nominal).

    Returns
    -------
    Diagram
    """
    dg = build_diagram(device, temperature_C)
    if q_drive_factor == 1.0:
        return dg
    if not q_drive_factor > 0:
        raise ValueError("q_drive_factor must be positive")
    vals = copy.deepcopy(dg.op.values)
    vals["mechanics"]["q_drive"] = vals["mechanics"]["q_drive"] * float(q_drive_factor)
    return Diagram(OperatingPoint(dg.op.temperature_C, vals), dg.phase_trim_rad)


def with_gains(dg: Diagram, kp: float | None = None, ki_per_s: float | None = None) -> PIController:
    """The diagram's PI block with other gains (limits kept).

    Parameters
    ----------
    dg : Diagram
    kp, ki_per_s : float, optional
        New gains (default: the diagram's).

    Returns
    -------
    PIController
    """
    return dataclasses.replace(dg.pi, kp=dg.pi.kp if kp is None else float(kp),
                               ki_per_s=dg.pi.ki_per_s if ki_per_s is None else float(ki_per_s))


@dataclass
class PlantParameters:
    """The averaged amplitude plant and sensor at one operating point.

    Attributes
    ----------
    temperature_C : float
    carrier_mode : str
        ``'normalized'`` (plant ``b/(s + 1/tau_d)``) or ``'pickoff'`` (plant ``b/s``).
    omega_rad_s : float
        Oscillation frequency of the steady state.
    q_drive : float
    tau_d_s : float
        Envelope time constant ``2 Q_d / omega_d``.
    plant_pole_rad_s : float
        ``1/tau_d`` (normalized carrier) or 0 (pickoff carrier).
    b_m_per_V_s : float
        Plant input gain: ``dA/dt`` per volt of PI output.
    amplitude_m : float
        Steady drive amplitude A_0.
    agc_effort_V : float
        Steady PI output u_0.
    vref_V : float
        Amplitude set-point at this temperature.
    loop_phase_error_rad : float
        delta.
    carrier_fundamental_V : float
        |C| at the steady state.
    comb_coef_N_per_V, k_mod_per_V, m_drive_kg : float
        Block parameters in b.
    sensor_gain_V_per_m : float
        ``(2/pi) G_r |H_dx H_ps|`` at the oscillation frequency.
    u_min_V, u_max_V : float
        PI output limits.
    """

    temperature_C: float
    carrier_mode: str
    omega_rad_s: float
    q_drive: float
    tau_d_s: float
    plant_pole_rad_s: float
    b_m_per_V_s: float
    amplitude_m: float
    agc_effort_V: float
    vref_V: float
    loop_phase_error_rad: float
    carrier_fundamental_V: float
    comb_coef_N_per_V: float
    k_mod_per_V: float
    m_drive_kg: float
    sensor_gain_V_per_m: float
    u_min_V: float
    u_max_V: float

    @property
    def loop_gain_per_V_s(self) -> float:
        """``b * sensor gain``: the plant-and-sensor gain (1/s per V/V of controller gain).

        Returns
        -------
        float
        """
        return self.b_m_per_V_s * self.sensor_gain_V_per_m

    def as_dict(self) -> dict:
        """Plain dict (JSON-ready).

        Returns
        -------
        dict
        """
        return dataclasses.asdict(self)


def plant_parameters(dg: Diagram) -> PlantParameters:
    """Linearise the averaged amplitude dynamics of ``dg`` around its steady state.

    Parameters
    ----------
    dg : Diagram

    Returns
    -------
    PlantParameters
    """
    ss = steady_state(dg)
    w = ss.omega_rad_s
    r = dg.resonator
    Hx = dg.drive_chain_response(w)
    Hps = dg.phase_shifter_response(w)
    carrier, _, _ = carrier_phasors(dg, Hx * ss.X, Hx * Hps * ss.X)
    delta = ss.loop_phase_error_rad
    k_comb = dg.comb_drive.linear_coef_N_per_V
    k_mod = dg.modulator.k_per_V
    b = k_comb * k_mod * abs(carrier) * np.cos(delta) / (2 * r.m_drive_kg * w)
    tau = r.ringdown_time_constant_s("drive")
    if dg.carrier_mode == "normalized":
        pole = 1.0 / tau
    elif dg.carrier_mode == "pickoff":
        pole = 0.0
    else:  # pragma: no cover - the device schema allows only the two
        raise ValueError(f"unknown carrier mode {dg.carrier_mode!r}")
    sensor = dg.amplitude_loop.sensor_gain(Hx * Hps)
    return PlantParameters(
        temperature_C=dg.temperature_C, carrier_mode=dg.carrier_mode, omega_rad_s=w, q_drive=r.q_drive,
        tau_d_s=tau, plant_pole_rad_s=pole, b_m_per_V_s=float(b), amplitude_m=ss.amplitude_m,
        agc_effort_V=ss.agc_effort_V, vref_V=dg.vref_V, loop_phase_error_rad=delta,
        carrier_fundamental_V=float(abs(carrier)), comb_coef_N_per_V=k_comb, k_mod_per_V=k_mod,
        m_drive_kg=r.m_drive_kg, sensor_gain_V_per_m=float(sensor), u_min_V=dg.pi.u_min_V,
        u_max_V=dg.pi.u_max_V)


def finite_difference_b(dg: Diagram, rel_step: float = 1e-3) -> float:
    """Check of ``b`` from the averaged steady state: ``b = (dA_0/du_0) / tau_d`` (normalized carrier).

    The steady state of ``A' = -A/tau_d + b u`` is ``A_0 = b tau_d u_0``; stepping the
    set-point moves both A_0 and u_0. (For the pickoff carrier u_0 does not depend on
    A_0 and the slope is undefined: NaN.)

    Parameters
    ----------
    dg : Diagram
    rel_step : float, optional
        Relative set-point step.

    Returns
    -------
    float
        b in m/(V s).
    """
    if dg.carrier_mode != "normalized":
        return float("nan")
    v = dg.vref_V
    hi, lo = steady_state(dg, vref_V=v * (1 + rel_step)), steady_state(dg, vref_V=v * (1 - rel_step))
    slope = (hi.amplitude_m - lo.amplitude_m) / (hi.agc_effort_V - lo.agc_effort_V)
    return float(slope / dg.resonator.ringdown_time_constant_s("drive"))


@dataclass
class LinearLoop:
    """The linearised amplitude loop as python-control systems with named signals.

    Attributes
    ----------
    params : PlantParameters
    plant : control.StateSpace
        ``u`` (V) -> ``A`` (m, deviation from A_0).
    sensor : control.StateSpace
        Rectifier describing gain, ``in`` (m) -> ``out`` (V mean).
    lpf : control.StateSpace
        The amplitude low-pass, ``in`` -> ``out`` = r.
    comparator : control.StateSpace
        ``in0`` (Vref) - ``in1`` (r) -> ``out`` = e.
    controller : control.StateSpace
        The PI, ``e`` -> ``u``.
    loop_gain : control.StateSpace
        ``L``: error ``e`` -> amplitude estimate ``r`` (controller, plant, sensor, LPF).
    closed_loop : control.StateSpace
        ``vref`` -> (``r``, ``u``, ``e``, ``A``).
    kp, ki_per_s : float
    """

    params: PlantParameters
    plant: control.StateSpace
    sensor: control.StateSpace
    lpf: control.StateSpace
    comparator: control.StateSpace
    controller: control.StateSpace
    loop_gain: control.StateSpace
    closed_loop: control.StateSpace
    kp: float
    ki_per_s: float

    def plant_and_sensor(self) -> control.StateSpace:
        """``u`` -> ``r``: plant, rectifier and low-pass in series (what the PI sees).

        Returns
        -------
        control.StateSpace
        """
        return control.interconnect(
            [self.plant, self.sensor, self.lpf], connections=[["rectifier.in", "plant.A"],
                                                              ["amplitude_lpf.in", "rectifier.out"]],
            inplist=["plant.u"], inputs=["u"], outlist=["amplitude_lpf.out"], outputs=["r"],
            name="plant_and_sensor")


def build_loop(dg: Diagram, kp: float | None = None, ki_per_s: float | None = None,
               params: PlantParameters | None = None) -> LinearLoop:
    """The linearised amplitude loop of ``dg`` (gains default to the diagram's PI).

    Parameters
    ----------
    dg : Diagram
    kp, ki_per_s : float, optional
        PI gains to analyse.
    params : PlantParameters, optional
        Precomputed :func:`plant_parameters` (saves the steady-state solve).

    Returns
    -------
    LinearLoop
    """
    p = params or plant_parameters(dg)
    pi_block = with_gains(dg, kp, ki_per_s)
    plant = control.ss([[-p.plant_pole_rad_s]], [[p.b_m_per_V_s]], [[1.0]], [[0.0]], name="plant",
                       inputs=["u"], outputs=["A"], states=["A_m"])
    sensor = control.ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[p.sensor_gain_V_per_m]],
                        name="rectifier", inputs=["in"], outputs=["out"])
    lpf = dg.amplitude_lpf.linear_model()
    comp = dg.comparator.linear_model()
    pi = pi_block.linear_model()
    blocks = [plant, sensor, lpf, pi]
    chain = [["rectifier.in", "plant.A"], ["amplitude_lpf.in", "rectifier.out"], ["plant.u", "pi.u"]]
    L = control.interconnect(blocks, connections=chain, inplist=["pi.e"], inputs=["e"],
                             outlist=["amplitude_lpf.out"], outputs=["r"], name="loop_gain")
    T = control.interconnect(
        blocks + [comp], connections=chain + [["comparator.in1", "amplitude_lpf.out"], ["pi.e", "comparator.out"]],
        inplist=["comparator.in0"], inputs=["vref"], outlist=["amplitude_lpf.out", "pi.u", "comparator.out", "plant.A"],
        outputs=["r", "u", "e", "A"], name="closed_loop")
    return LinearLoop(p, plant, sensor, lpf, comp, pi, L, T, pi_block.kp, pi_block.ki_per_s)


def step_metrics(t_s: np.ndarray, y: np.ndarray, y_initial: float, y_final: float,
                 band: float = SETTLING_BAND) -> dict:
    """Settling time and overshoot of a step response, defined as ``control.step_info`` does.

    The response is normalised to ``(y - y_initial) / (y_final - y_initial)``; the
    settling time is the first sample time after which it stays within ``band`` of 1,
    measured from ``t_s[0]`` (the step); the overshoot is ``100 (max - 1)`` percent.

    Parameters
    ----------
    t_s : ndarray
        Times from the step (the step at ``t_s[0]``).
    y : ndarray
        Response.
    y_initial, y_final : float
        Values before the step and after it has settled.
    band : float, optional

    Returns
    -------
    dict
        ``settling_time_s`` (NaN if never settled), ``overshoot_pct``, ``peak_time_s``.
    """
    t = np.asarray(t_s, dtype=float)
    yn = (np.asarray(y, dtype=float) - y_initial) / (y_final - y_initial)
    outside = np.flatnonzero(np.abs(yn - 1.0) >= band)
    if outside.size == 0:
        ts = 0.0
    elif outside[-1] + 1 < len(t):
        ts = float(t[outside[-1] + 1] - t[0])
    else:
        ts = float("nan")
    k = int(np.argmax(yn))
    return dict(settling_time_s=ts, overshoot_pct=float(max(0.0, 100.0 * (yn[k] - 1.0))),
                peak_time_s=float(t[k] - t[0]))


@dataclass
class LoopMetrics:
    """Frequency- and time-domain figures of the linearised loop at one operating point.

    Attributes
    ----------
    temperature_C, q_drive_factor, kp, ki_per_s : float
    gain_margin_db, phase_margin_deg : float
        From ``control.margin`` (inf when the phase never reaches -180 deg).
    crossover_rad_s : float
        Gain-crossover frequency.
    phase_crossover_rad_s : float
        Phase-crossover frequency (NaN if none).
    bandwidth_Hz : float
        Closed-loop -3 dB bandwidth Vref -> r (``control.bandwidth``).
    settling_time_s, overshoot_pct, peak_time_s : float
        Step response Vref -> r (``control.step_info`` with a 2 % band).
    u_peak_V : float
        Peak PI output for a :data:`STEP_FRACTION` Vref step from the steady state.
    u0_V : float
        Steady PI output.
    closed_loop_poles : list of complex
    params : PlantParameters
    t_s, r_unit, u_unit : ndarray
        Unit-step responses (for plots).
    """

    temperature_C: float
    q_drive_factor: float
    kp: float
    ki_per_s: float
    gain_margin_db: float
    phase_margin_deg: float
    crossover_rad_s: float
    phase_crossover_rad_s: float
    bandwidth_Hz: float
    settling_time_s: float
    overshoot_pct: float
    peak_time_s: float
    u_peak_V: float
    u0_V: float
    closed_loop_poles: list
    params: PlantParameters
    t_s: np.ndarray = field(repr=False, default=None)
    r_unit: np.ndarray = field(repr=False, default=None)
    u_unit: np.ndarray = field(repr=False, default=None)

    def as_dict(self, with_series: bool = False) -> dict:
        """JSON-ready dict.

        Parameters
        ----------
        with_series : bool, optional
            Include the step-response arrays.

        Returns
        -------
        dict
        """
        d = {k: getattr(self, k) for k in ("temperature_C", "q_drive_factor", "kp", "ki_per_s", "gain_margin_db",
                                           "phase_margin_deg", "crossover_rad_s", "phase_crossover_rad_s",
                                           "bandwidth_Hz", "settling_time_s", "overshoot_pct", "peak_time_s",
                                           "u_peak_V", "u0_V")}
        d["crossover_Hz"] = self.crossover_rad_s / (2 * np.pi)
        d["closed_loop_poles"] = [[float(p.real), float(p.imag)] for p in self.closed_loop_poles]
        d["plant"] = self.params.as_dict()
        if with_series:
            d.update(t_s=self.t_s.tolist(), r_unit=self.r_unit.tolist(), u_unit=self.u_unit.tolist())
        return d


def step_time_grid(poles: np.ndarray, n: int = 12001, t_max_s: float = 5.0) -> np.ndarray:
    """Time grid long enough for the slowest closed-loop pole to decay (7 time constants).

    Parameters
    ----------
    poles : ndarray
        Closed-loop poles.
    n : int, optional
    t_max_s : float, optional
        Upper bound of the horizon.

    Returns
    -------
    ndarray
    """
    re = np.abs(np.real(poles))
    re = re[re > 1e-9]
    slow = re.min() if re.size else 1.0
    return np.linspace(0.0, float(np.clip(7.0 / slow, 0.02, t_max_s)), n)


def analyze_loop(dg: Diagram, kp: float | None = None, ki_per_s: float | None = None,
                 q_drive_factor: float = 1.0, params: PlantParameters | None = None,
                 step_fraction: float = STEP_FRACTION) -> LoopMetrics:
    """Margins, bandwidth and step metrics of the linearised loop of ``dg``.

    Parameters
    ----------
    dg : Diagram
        The diagram (already at its temperature and Q; see :func:`diagram_at`).
    kp, ki_per_s : float, optional
        Gains (default: the diagram's).
    q_drive_factor : float, optional
        Recorded in the result (the Q scaling already applied to ``dg``).
    params : PlantParameters, optional
        Precomputed plant parameters.
    step_fraction : float, optional
        Set-point step for the PI output check, as a fraction of Vref.

    Returns
    -------
    LoopMetrics
    """
    loop = build_loop(dg, kp, ki_per_s, params)
    p = loop.params
    L = loop.loop_gain
    gm, pm, wpc, wgc = control.margin(L)
    gm_db = float(20 * np.log10(gm)) if np.isfinite(gm) and gm > 0 else float("inf")
    T_r = control.feedback(L, 1)          # Vref -> r with unity feedback (the comparator)
    bw = float(control.bandwidth(T_r)) / (2 * np.pi)
    poles = np.asarray(control.poles(T_r))
    t = step_time_grid(poles)
    resp = control.step_response(loop.closed_loop, T=t, input=0)
    r_unit = np.asarray(resp.outputs[0]).ravel()
    u_unit = np.asarray(resp.outputs[1]).ravel()
    # the closed loop has integral action: r settles at Vref exactly (T_r(0) = 1)
    info = control.step_info(r_unit, T=t, yfinal=float(np.real(T_r.dcgain())),
                             SettlingTimeThreshold=SETTLING_BAND)
    du = step_fraction * p.vref_V * u_unit
    u_peak = p.agc_effort_V + float(du.max())
    return LoopMetrics(
        temperature_C=p.temperature_C, q_drive_factor=float(q_drive_factor), kp=loop.kp, ki_per_s=loop.ki_per_s,
        gain_margin_db=gm_db, phase_margin_deg=float(pm), crossover_rad_s=float(wgc),
        phase_crossover_rad_s=float(wpc) if np.isfinite(wpc) else float("nan"), bandwidth_Hz=bw,
        settling_time_s=float(info["SettlingTime"]), overshoot_pct=float(info["Overshoot"]),
        peak_time_s=float(info["PeakTime"]), u_peak_V=u_peak, u0_V=p.agc_effort_V,
        closed_loop_poles=list(poles), params=p, t_s=t, r_unit=r_unit, u_unit=u_unit)


def pole_zero_rule(dg_ref: Diagram, crossover_fraction_of_lpf: float = 0.2) -> tuple[float, float]:
    """The pole-zero-cancellation rule of physics brief section 3 at the reference diagram.

    ``Ki/Kp = 1/tau_d`` cancels the plant pole; the crossover
    ``omega_c = Kp b (2/pi) G_r |H_dx H_ps|`` is put at ``crossover_fraction_of_lpf``
    times the amplitude low-pass corner (``omega_c <= omega_f / 5``). With the
    'pickoff' carrier the plant is an integrator with no pole to cancel; the PI zero is
    then put at ``omega_c / 5`` (a common choice for a type-2 loop).

    Parameters
    ----------
    dg_ref : Diagram
        Diagram at the design temperature (25 C).
    crossover_fraction_of_lpf : float, optional

    Returns
    -------
    tuple of float
        (kp, ki_per_s)
    """
    p = plant_parameters(dg_ref)
    w_f = 2 * np.pi * dg_ref.amplitude_lpf.f_c_Hz
    kp = crossover_fraction_of_lpf * w_f / p.loop_gain_per_V_s
    if p.plant_pole_rad_s > 0:
        return float(kp), float(kp * p.plant_pole_rad_s)
    return float(kp), float(kp * crossover_fraction_of_lpf * w_f / 5.0)
