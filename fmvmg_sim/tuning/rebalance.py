"""The force-to-rebalance loop's linear model, its margins over temperature and Q_s, and its check in simulation.

The loop is linearised in the envelope frame (the averaged model's sense mode,
:meth:`blocks.TwoModeResonator.envelope_mode`): the plant from the controller output ``u_I`` to the
demodulated error ``e_I`` is the sense mode's slow pole with its residue and feedthrough, seen through the
pickoff, the sense amplifiers (their gain and phase at the drive frequency) and the demodulator with the
trimmed reference. The rate reaches the same mode as the Coriolis force; the output passes the output
low-pass (14). The quadrature loop, about 1 Hz, is left open here: it moves nothing at the rate loop's
frequencies. The same model gives the open sense chain's bandwidth (the Coriolis path and the output
low-pass alone), for comparison.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import control
import numpy as np

from ..averaged import carrier_phasors, steady_state
from ..device import Device
from ..diagram import Diagram, build_diagram
from ..errors import InputError
from ..paths import scenarios_dir
from ..profiles import PiecewiseProfile
from ..rebalance import design_gains
from ..scenario import load_scenario

#: Frequencies of the bandwidth search (Hz).
_F_HZ = np.logspace(-1, 3.5, 2000)


def _cmat(z: complex) -> np.ndarray:
    return np.array([[z.real, -z.imag], [z.imag, z.real]])


def loop_models(dg: Diagram) -> dict:
    """python-control models of the sense chain at the diagram's operating point.

    Parameters
    ----------
    dg : Diagram

    Returns
    -------
    dict
        ``plant`` (u_I -> e_I, None without a rate loop), ``coriolis`` (rate in deg/s -> e_I for the loop, or
        -> rate_V of the open chain), ``controller`` (e_I -> u_I, None without a rate loop) and ``output``
        (the output low-pass, unit DC gain times its gain).
    """
    ss = steady_state(dg)
    w, A = ss.omega_rad_s, ss.amplitude_m
    Hx, Hps = dg.drive_chain_response(w), dg.phase_shifter_response(w)
    C0, R_I, R_Q = carrier_phasors(dg, Hx * A, Hx * Hps * A)
    r = dg.resonator
    s1, rs, ds = r.envelope_mode("sense", w)
    kY = dg.sense_amps_response(w) * dg.sense_pickoff.gain_V_per_m
    z = kY * np.conj(R_I)
    g_d = 0.5 * dg.demodulator.k_per_V

    def path(F: complex):  # e per unit input for a sense force phasor F per unit input
        return control.ss(_cmat(s1), [[(rs * F).real], [(rs * F).imag]], [[g_d * z.real, -g_d * z.imag]],
                          [[g_d * (z * ds * F).real]])

    F_W = -2j * w * r.m_coriolis_kg * A * np.pi / 180.0  # Coriolis force per deg/s
    ol = dg.output_lpf.linear_model()
    loop = dg.sense_loop
    ftr = loop is not None and loop.force_rebalance
    out = dict(coriolis=path(F_W), output=control.ss(ol.A, ol.B, ol.C, ol.D), plant=None, controller=None)
    if ftr:
        p_i, _ = loop.polarities(dg, w, A, C0, R_I, R_Q)
        out["plant"] = path(p_i * loop.force_per_V(C0))
        blk = loop.controller
        out["controller"] = control.ss(*blk.state_space_matrices())
    return out


@dataclass
class RebalanceMetrics:
    """Linear figures of the sense chain at one temperature and Q_s factor.

    Attributes
    ----------
    temperature_C, q_factor : float
    phase_margin_deg, gain_margin_dB : float
        Of the rate loop (infinite gain margin as ``inf``); NaN for the open chain.
    crossover_Hz : float
        Loop gain crossover (NaN for the open chain).
    bandwidth_Hz : float
        First frequency where the rate output leaves +-3 dB of its DC value.
    peak_dB : float
        Largest gain of the rate output relative to DC (the open chain's resonance at the split).
    settling_s : float
        2 % settling time of the rate output's step response.
    stable : bool
    """

    temperature_C: float
    q_factor: float
    phase_margin_deg: float
    gain_margin_dB: float
    crossover_Hz: float
    bandwidth_Hz: float
    peak_dB: float
    settling_s: float
    stable: bool

    def as_dict(self) -> dict:
        """Plain dict.

        Returns
        -------
        dict
        """
        return asdict(self)


def rate_response(models: dict) -> control.StateSpace:
    """Rate (deg/s) to ``rate_V`` of the sense chain: through the closed rate loop when it has one.

    Parameters
    ----------
    models : dict
        :func:`loop_models`.

    Returns
    -------
    control.StateSpace
    """
    if models["plant"] is None:
        return control.series(models["coriolis"], models["output"])
    P, C, Pw = models["plant"], models["controller"], models["coriolis"]
    # u = C e, e = P u + Pw W  ->  u = C Pw W / (1 - C P)
    u = control.series(Pw, control.feedback(C, P, sign=+1))
    return control.series(u, models["output"])


def analyze(dg: Diagram, temperature_C: float, q_factor: float = 1.0) -> RebalanceMetrics:
    """Margins, bandwidth and settling time of the sense chain of ``dg``.

    Parameters
    ----------
    dg : Diagram
    temperature_C, q_factor : float
        Labels of the operating point.

    Returns
    -------
    RebalanceMetrics
    """
    m = loop_models(dg)
    pm = gm = wc = np.nan
    T = rate_response(m)
    poles = control.poles(T)
    stable = bool(np.all(np.real(poles) < 0))
    if m["plant"] is not None:
        L = -1.0 * control.series(m["plant"], m["controller"])  # negative feedback around -P C
        gm_, pm_, _, wc_ = control.stability_margins(L)[:4]
        gm = 20 * np.log10(gm_) if np.isfinite(gm_) and gm_ > 0 else np.inf
        pm, wc = float(pm_), float(wc_) / (2 * np.pi)
    resp = np.abs(np.asarray(control.frequency_response(T, 2 * np.pi * _F_HZ).magnitude).ravel())
    dc = abs(np.asarray(control.dcgain(T)).item())
    rel = resp / dc
    below = np.flatnonzero((rel < 1 / np.sqrt(2)) | (rel > np.sqrt(2)))  # out of the +-3 dB band
    bw = float(_F_HZ[below[0]]) if len(below) else float(_F_HZ[-1])
    peak = float(20 * np.log10(rel.max()))
    t = np.linspace(0, 2.0, 40001)
    y = np.asarray(control.step_response(T, t).outputs).ravel() / dc
    out_band = np.flatnonzero(np.abs(y - 1) > 0.02)
    settle = float(t[out_band[-1]]) if len(out_band) else 0.0
    return RebalanceMetrics(temperature_C, q_factor, pm, gm, wc, bw, peak, settle, stable)


def _device_at_q(device: Device, q_factor: float) -> Device:
    if q_factor == 1.0:
        return device
    q = device.values["mechanics"]["q_sense"]
    return device.with_overrides({"mechanics": {"q_sense": q * q_factor}}, "Q_s tolerance")


def robust_table(device: Device, temperatures_C, q_factors=(0.8, 1.0, 1.2)) -> list[RebalanceMetrics]:
    """:func:`analyze` over a grid of temperatures and sense-mode Q factors.

    Parameters
    ----------
    device : Device
    temperatures_C : sequence of float
    q_factors : sequence of float, optional

    Returns
    -------
    list of RebalanceMetrics
    """
    out = []
    for qf in q_factors:
        dev = _device_at_q(device, qf)
        for T in temperatures_C:
            out.append(analyze(build_diagram(dev, float(T)), float(T), float(qf)))
    return out


def with_gains(device: Device, gains: dict) -> Device:
    """The device with the rate loop closed and these gains.

    Parameters
    ----------
    device : Device
    gains : dict
        ``kp``, ``ki_per_s``, ``kd_s``.

    Returns
    -------
    Device
    """
    if "rebalance" not in device.values["circuit"]:
        raise InputError("the device has no force-rebalance parameters [circuit.rebalance]", "circuit.rebalance")
    return device.with_overrides({"circuit": {"sense": {"topology": "force-rebalance"}, "rebalance": gains}},
                                 "fmvmg tune --loop rebalance")


def design(device: Device, bandwidth_Hz: float, zeta: float = 0.7) -> dict:
    """Gains by :func:`fmvmg_sim.rebalance.design_gains` at the device's reference temperature.

    Parameters
    ----------
    device : Device
    bandwidth_Hz : float
    zeta : float, optional

    Returns
    -------
    dict
    """
    if not bandwidth_Hz > 0:
        raise InputError(f"expected > 0, got {bandwidth_Hz:g}", "--bandwidth-Hz")
    dev = with_gains(device, {})
    return design_gains(build_diagram(dev, dev.reference_temperature_C), bandwidth_Hz, zeta)


#: Rate step of the simulation check (deg/s) and its time (s).
STEP_DPS, T_STEP = 50.0, 0.1


@dataclass
class RateStepCheck:
    """A rate step in the carrier engine beside its prediction.

    Attributes
    ----------
    temperature_C : float
    scale_factor_V_per_dps, scale_factor_predicted : float
        Measured (step size over rate step) and from the averaged model.
    bias_V, bias_predicted_V : float
        Zero-rate output before the step, measured and averaged.
    settling_s, settling_predicted_s : float
        2 % settling of the step, measured and from the linear model.
    """

    temperature_C: float
    scale_factor_V_per_dps: float
    scale_factor_predicted: float
    bias_V: float
    bias_predicted_V: float
    settling_s: float
    settling_predicted_s: float

    def as_dict(self) -> dict:
        """Plain dict.

        Returns
        -------
        dict
        """
        return asdict(self)


def step_metrics(res, hold_s: float) -> dict:
    """Bias, scale factor, 2 % settling time and quadrature output of a rate step of :data:`STEP_DPS` at
    :data:`T_STEP` held ``hold_s``.

    Parameters
    ----------
    res : SimResult
    hold_s : float

    Returns
    -------
    dict
    """
    t, r = res.channels["time_s"], res.channels["rate_V"]
    pre = (t > T_STEP - 0.03) & (t <= T_STEP)
    post = t > T_STEP + hold_s - 0.05
    bias, final = float(r[pre].mean()), float(r[post].mean())
    late = np.flatnonzero((np.abs(r - final) > 0.02 * abs(final - bias)) & (t > T_STEP))
    return dict(bias=bias, sf=(final - bias) / STEP_DPS, settle=float(t[late[-1]] - T_STEP) if len(late) else 0.0,
                quad=float(res.channels["quadrature_V"][post].mean()))


def step_scenario(device: Device, temperature_C: float, hold_s: float, fidelity: str = "carrier"):
    """A noise-free rate step at one temperature on ``device``, started on the steady state.

    Parameters
    ----------
    device : Device
    temperature_C : float
    hold_s : float
        Simulated time after the step.
    fidelity : {"carrier", "envelope"}, optional

    Returns
    -------
    Scenario
    """
    scn = load_scenario(scenarios_dir() / "force_rebalance_rate.toml", fidelity=fidelity)
    T = float(temperature_C)
    end = T_STEP + hold_s
    return scn.replace(
        scenario={"duration_s": end, "envelope_step_s": 0.0005}, initial={"state": "steady"},
        noise={k: False for k in ("brownian", "electronic", "flicker", "quantization", "rate_random_walk")},
        device=device, device_nominal=device,
        temperature=PiecewiseProfile(np.array([0.0, end]), np.array([T, T]), []),
        rate=PiecewiseProfile(np.array([0.0, T_STEP, T_STEP, end]), np.array([0.0, 0.0, STEP_DPS, STEP_DPS]), []))


def check_rate_step(device: Device, temperature_C: float, hold_s: float = 0.25) -> RateStepCheck:
    """A rate step in the carrier engine against the averaged scale factor and bias and the linear settling time.

    Parameters
    ----------
    device : Device
    temperature_C : float
    hold_s : float, optional

    Returns
    -------
    RateStepCheck
    """
    from ..carrier.engine import run_carrier  # the engine compiles its step on first use
    m = step_metrics(run_carrier(step_scenario(device, temperature_C, hold_s), progress=False), hold_s)
    dg = build_diagram(device, float(temperature_C))
    ss0 = steady_state(dg)
    sf = (steady_state(dg, np.deg2rad(STEP_DPS)).rate_V - ss0.rate_V) / STEP_DPS
    return RateStepCheck(float(temperature_C), m["sf"], float(sf), m["bias"], float(ss0.rate_V), m["settle"],
                         analyze(dg, float(temperature_C)).settling_s)


def rebalance_report(device: Device, temperatures_C, grid_temperatures_C, q_factors, bandwidth_Hz: float | None = None,
                     simulate: bool = True, log=None) -> dict:
    """``fmvmg tune --loop rebalance``: the rate loop's gains, margins over a grid and checks in simulation.

    Parameters
    ----------
    device : Device
    temperatures_C : sequence of float
        Temperatures of the simulation checks.
    grid_temperatures_C : sequence of float
        Temperatures of the margin grid.
    q_factors : sequence of float
        Sense-mode Q factors of the margin grid (relative).
    bandwidth_Hz : float, optional
        Design the gains for this integral pole (:func:`design`); default: check the device's gains.
    simulate : bool, optional
        Run the carrier-engine rate steps.
    log : callable, optional

    Returns
    -------
    dict
        ``gains``, ``grid`` (per temperature and Q factor), ``worst``, ``checks``, ``open_loop`` (the open
        chain's bandwidth and settling at the reference temperature, for comparison).
    """
    log = log or (lambda m: None)
    fb = device.values["circuit"].get("rebalance")
    if fb is None:
        raise InputError("the device has no force-rebalance parameters [circuit.rebalance]", "circuit.rebalance")
    gains = design(device, bandwidth_Hz) if bandwidth_Hz is not None else \
        {k: float(fb[k]) for k in ("kp", "ki_per_s", "kd_s")}
    dev = with_gains(device, gains)
    log(f"margins over {len(grid_temperatures_C)} temperatures x {len(q_factors)} Q_s factors")
    grid = robust_table(dev, grid_temperatures_C, q_factors)
    worst = dict(phase_margin_deg=min(m.phase_margin_deg for m in grid),
                 gain_margin_dB=min(m.gain_margin_dB for m in grid),
                 bandwidth_Hz_min=min(m.bandwidth_Hz for m in grid), bandwidth_Hz_max=max(m.bandwidth_Hz for m in grid),
                 settling_s_max=max(m.settling_s for m in grid), stable=all(m.stable for m in grid))
    checks = []
    if simulate:
        for T in temperatures_C:
            log(f"carrier-engine rate step at {T:g} C")
            checks.append(check_rate_step(dev, T).as_dict())
    T0 = device.reference_temperature_C
    open_dev = device.with_overrides({"circuit": {"sense": {"topology": "open-loop"}}}, "open loop") \
        if "sense" in device.values["circuit"] else device
    return dict(gains=gains, grid=[m.as_dict() for m in grid], worst=worst, checks=checks,
                open_loop=analyze(build_diagram(open_dev, T0), T0).as_dict())


def format_rebalance_table(report: dict) -> str:
    """The report as a text table.

    Parameters
    ----------
    report : dict
        :func:`rebalance_report`.

    Returns
    -------
    str
    """
    g = report["gains"]
    lines = [f"force-to-rebalance gains: Kp {g['kp']:.4g}, Ki {g['ki_per_s']:.4g} 1/s, Kd {g['kd_s']:.4g} s",
             f"{'T (C)':>7} {'Q_s x':>6} {'PM (deg)':>9} {'GM (dB)':>8} {'BW (Hz)':>8} {'settle (ms)':>12}"]
    for m in report["grid"]:
        lines.append(f"{m['temperature_C']:7.1f} {m['q_factor']:6.2f} {m['phase_margin_deg']:9.1f} "
                     f"{m['gain_margin_dB']:8.1f} {m['bandwidth_Hz']:8.1f} {1e3 * m['settling_s']:12.1f}")
    w = report["worst"]
    lines.append(f"worst case: PM {w['phase_margin_deg']:.1f} deg, GM {w['gain_margin_dB']:.1f} dB, bandwidth "
                 f"{w['bandwidth_Hz_min']:.1f}..{w['bandwidth_Hz_max']:.1f} Hz, settling <= "
                 f"{1e3 * w['settling_s_max']:.1f} ms, {'stable' if w['stable'] else 'UNSTABLE'}")
    o = report["open_loop"]
    lines.append(f"open sense chain (for comparison): bandwidth {o['bandwidth_Hz']:.1f} Hz (peak {o['peak_dB']:+.1f} dB "
                 f"at the split), settling {1e3 * o['settling_s']:.0f} ms")
    for c in report["checks"]:
        lines.append(f"carrier check {c['temperature_C']:g} C: SF {c['scale_factor_V_per_dps']:.5g} V/(deg/s) "
                     f"(averaged {c['scale_factor_predicted']:.5g}), bias {c['bias_V']:.4g} V "
                     f"(averaged {c['bias_predicted_V']:.4g}), settling {1e3 * c['settling_s']:.1f} ms "
                     f"(linear {1e3 * c['settling_predicted_s']:.1f})")
    return "\n".join(lines)


__all__ = ["rebalance_report", "format_rebalance_table", "STEP_DPS", "T_STEP", "RateStepCheck", "step_metrics", "step_scenario", "check_rate_step", "loop_models", "rate_response", "analyze", "RebalanceMetrics", "robust_table", "with_gains", "design"]
