"""The PLL drive: its blocks at an operating point, its linear core and its locked steady state.

With ``[circuit.drive] topology = "pll"`` the phase shifter, rectifier and carrier normaliser of
paper 000's loop give way to a phase-locked loop::

    resonator.x -> drive pickoff -> drive amp (1) = v_x
    v_x x cos(theta + trim) -> low-pass -> loop filter (PI, clamped) = v_tune -> oscillator: f = f_free + K_vco v_tune
    v_x x sin(theta + trim) -> amplitude low-pass (4) = r ;  e = Vref - r -> AGC PI (7) = u
    v_ac = K_mod u Vdac cos(theta) -> comb drive (10) -> resonator F_x
    rate and quadrature: v_s demodulated against Vdac cos(theta + trim_r), Vdac sin(theta + trim_r)

The core (resonator, pickoffs, amplifiers, comb drive) is the self-oscillating loop's with the
modulator gain ``g = 0`` and ``v_ac`` an input (:meth:`fmvmg_sim.diagram.Diagram.core_system`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from blocks import LowPass2, PIController
from blocks.nco import ControlledOscillator
from blocks.phase_detector import QuadratureDetector

from .diagram import CORE_OUTPUTS, Diagram, build_diagram, design_phase_trim
from .device import Device
from .numerics.layout import lpf_step


#: The phase loop's fields in a step's parameters (every model that runs the PLL): the oscillator's free frequency
#: and gain, the phase detector's trim (cos, sin) and amplitude gain, the detector's low-pass discretised for the
#: step, and the loop filter (PI gains and output clamp).
PHASE_LOOP_FIELDS = [
    ("f_free", ()), ("k_vco", ()), ("pd_cos", ()), ("pd_sin", ()), ("k_amp", ()),
    ("Phi_pd", (2, 2)), ("Gam_pd", (2,)), ("kp_pll", ()), ("ki_pll", ()), ("v_min", ()), ("v_max", ()),
]


def regulate_phase(P, p, s_pd, integ, pd, h, ops):
    """The phase loop over one step: the detector's low-pass driven by the step's phase reading ``pd``, then the
    loop filter (PI, clamped, anti-windup) on its output.

    Parameters
    ----------
    P : callable
        ``P(p, name)`` reads a field of :data:`PHASE_LOOP_FIELDS` from the packed parameters.
    p : sequence
        The step's packed parameters (numbers or CasADi symbols).
    s_pd : sequence
        The low-pass's two states at the start of the step.
    integ : float or symbol
        The loop filter's integrator.
    pd : float or symbol
        The phase detector's reading over the step.
    h : float or symbol
        Step length (s).
    ops : object
        Math backend.

    Returns
    -------
    tuple
        ``(s_pd, integ, v_tune)`` at the end of the step.
    """
    s_pd1 = lpf_step(P(p, "Phi_pd"), P(p, "Gam_pd"), s_pd, pd)
    loop = PIController(kp=P(p, "kp_pll"), ki_per_s=P(p, "ki_pll"), u_min_V=P(p, "v_min"), u_max_V=P(p, "v_max"))
    integ1, v_tune1 = loop.carrier_step(integ, s_pd1[0], h, ops)
    return s_pd1, integ1, v_tune1


@dataclass
class PLLDrive:
    """The PLL drive's blocks at one operating point, beside the diagram's shared ones.

    Parameters
    ----------
    dg : Diagram
        The diagram at the operating point (resonator, pickoffs, amplifiers, AGC, sense chain).
    nco : ControlledOscillator
    detector : QuadratureDetector
        Phase detector and amplitude channel on ``v_x``.
    pd_lpf : LowPass2
        The phase detector's low-pass.
    loop_filter : PIController
        PI with the tuning range as its clamp.
    rate_trim_rad : float
        Phase of the rate demodulation reference against the oscillator's ``cos(theta)``.
    """

    dg: Diagram
    nco: ControlledOscillator
    detector: QuadratureDetector
    pd_lpf: LowPass2
    loop_filter: PIController
    rate_trim_rad: float

    def core_system(self, rate_rad_s: float = 0.0, k_drive_extra_N_per_m: float = 0.0):
        """The linear core with ``v_ac`` as its last input (``g = 0``).

        Parameters
        ----------
        rate_rad_s : float, optional
        k_drive_extra_N_per_m : float, optional
            Duffing describing-function stiffness.

        Returns
        -------
        control.StateSpace
        """
        return self.dg.core_system(0.0, rate_rad_s, k_drive_extra_N_per_m, v_ac_input=True)

    def drive_voltage_V(self, u_V: float) -> float:
        """Amplitude of ``v_ac`` for AGC output ``u_V``: ``K_mod u Vdac``.

        Parameters
        ----------
        u_V : float

        Returns
        -------
        float
        """
        return self.dg.modulator.k_per_V * u_V * self.dg.vdac_V


def _reference_trims(device: Device) -> tuple[float, float]:
    """The phase detector's trim and the rate reference's trim, designed at the reference temperature."""
    ref = device.reference_diagram
    w = ref.omega_drive_rad_s
    setting = device.values["circuit"].get("pll", {}).get("pd_trim", "auto")
    pd_trim = float(np.angle(ref.drive_chain_response(w))) if setting == "auto" else float(setting)
    # the self-oscillating loop's trim plus the phase its reference (the phase-shifted pickoff) carried against
    # the drive velocity: what the oscillator's cos(theta), in phase with the force, needs at resonance
    carried = float(np.angle(ref.drive_chain_response(w)) + np.angle(ref.phase_shifter_response(w)) - np.pi / 2)
    rate_trim = design_phase_trim(device) + carried + (pd_trim - float(np.angle(ref.drive_chain_response(w))))
    return pd_trim, rate_trim


def build_pll_drive(device: Device, temperature_C: float, board_C: float | None = None,
                    dg: Diagram | None = None) -> PLLDrive:
    """The PLL drive of ``device`` at a die and a board temperature.

    Parameters
    ----------
    device : Device
        A device with ``circuit.drive.topology = "pll"``.
    temperature_C : float
        Die temperature.
    board_C : float, optional
        Board temperature (default: the die's).
    dg : Diagram, optional
        The diagram at these temperatures, if already built.

    Returns
    -------
    PLLDrive
    """
    dg = build_diagram(device, temperature_C, board_C=board_C) if dg is None else dg
    p = dg.op["circuit"]["pll"]
    pd_trim, rate_trim = _reference_trims(device)
    drift = dg.op.values.get("demod_phase_drift_rad", 0.0)
    # the amplitude channel reads v_x on the rectifier's scale, so one Vref holds one amplitude in both drives
    detector = QuadratureDetector(trim_rad=pd_trim, k_pd=1.0, k_amp=dg.rectifier.describing_gain())
    return PLLDrive(dg=dg, nco=ControlledOscillator(f_free_Hz=p["f_free_Hz"], k_vco_Hz_per_V=p["k_vco_Hz_per_V"]),
                    detector=detector, pd_lpf=LowPass2(name="pd_lpf", f_c_Hz=p["pd_lpf_f_c_Hz"], gain=1.0),
                    loop_filter=PIController(name="loop_filter", kp=p["kp"], ki_per_s=p["ki_per_s"],
                                             u_min_V=p["v_min_V"], u_max_V=p["v_max_V"]),
                    rate_trim_rad=rate_trim + drift)


@dataclass
class PLLSteadyState:
    """The locked PLL drive's steady state at one operating point and rate.

    Attributes
    ----------
    omega_rad_s, f_Hz : float
        Lock frequency (the oscillator's).
    amplitude_m : float
        Drive displacement amplitude.
    v_x_amplitude_V : float
        Drive pickoff amplitude.
    agc_effort_V : float
        AGC output u.
    v_tune_V : float
        Loop-filter output that holds the oscillator at the lock frequency.
    rate_V, quadrature_V : float
        Demodulated outputs (after the output low-pass's DC gain).
    locked : bool
        The tuning voltage is within the loop filter's range.
    """

    omega_rad_s: float
    f_Hz: float
    amplitude_m: float
    v_x_amplitude_V: float
    agc_effort_V: float
    v_tune_V: float
    rate_V: float
    quadrature_V: float
    locked: bool


def _core_matrices(pll: PLLDrive, rate_rad_s: float, kx: float) -> tuple:
    core = pll.core_system(rate_rad_s, kx)
    return np.asarray(core.A), np.asarray(core.B)[:, -1], np.asarray(core.C)


def _responses(mats: tuple, omega: float) -> dict:
    """Phasors of the core's outputs per volt of ``v_ac`` at ``omega`` (``mats`` from :func:`_core_matrices`)."""
    A, B, C = mats
    h = C @ np.linalg.solve(1j * omega * np.eye(A.shape[0]) - A, B)
    return {name: complex(h[k]) for k, name in enumerate(CORE_OUTPUTS)}


def lock_frequency(pll: PLLDrive, rate_rad_s: float = 0.0, kx: float = 0.0) -> float:
    """The frequency at which the phase detector reads zero: the loop's lock point (rad/s).

    Parameters
    ----------
    pll : PLLDrive
    rate_rad_s : float, optional
    kx : float, optional
        Duffing describing-function stiffness.

    Returns
    -------
    float
    """
    res = pll.dg.resonator
    w0 = 2 * np.pi * res.f_drive_Hz
    half_bw = w0 / (2 * res.q_drive)
    mats = _core_matrices(pll, rate_rad_s, kx)

    def pd(w):
        return pll.detector.baseband(_responses(mats, w)["v_x"])[0]

    lo, hi = w0 - 20 * half_bw, w0 + 20 * half_bw
    return float(brentq(pd, lo, hi, xtol=1e-9 * w0))


def pll_steady_state(pll: PLLDrive, rate_rad_s: float = 0.0, vref_V: float | None = None) -> PLLSteadyState:
    """The locked steady state: lock frequency, AGC effort for the set-point, outputs.

    Parameters
    ----------
    pll : PLLDrive
    rate_rad_s : float, optional
        Constant input rate.
    vref_V : float, optional
        Amplitude set-point (default: the diagram's Vref).

    Returns
    -------
    PLLSteadyState
    """
    dg = pll.dg
    vref = dg.vref_V if vref_V is None else vref_V
    v_amp = vref / pll.detector.k_amp
    kx = 0.0
    for _ in range(3):  # the Duffing stiffness at the amplitude, which the lock frequency moves little
        w = lock_frequency(pll, rate_rad_s, kx)
        r = _responses(_core_matrices(pll, rate_rad_s, kx), w)
        u = v_amp / (abs(r["v_x"]) * dg.modulator.k_per_V * dg.vdac_V)
        amp_m = abs(r["x"]) * pll.drive_voltage_V(u)
        kx_new = dg.resonator.duffing_stiffness(amp_m)
        if kx_new == kx:
            break
        kx = kx_new
    v_ac = pll.drive_voltage_V(u)
    V_s = r["v_s"] * v_ac
    R_I = dg.vdac_V * np.exp(1j * pll.rate_trim_rad)
    k_out = dg.output_lpf.gain
    v_tune = (w / (2 * np.pi) - pll.nco.f_free_Hz) / pll.nco.k_vco_Hz_per_V
    lf = pll.loop_filter
    return PLLSteadyState(omega_rad_s=w, f_Hz=w / (2 * np.pi), amplitude_m=amp_m, v_x_amplitude_V=v_amp,
                          agc_effort_V=float(u), v_tune_V=float(v_tune),
                          rate_V=float(k_out * dg.demodulator.baseband(V_s, R_I)),
                          quadrature_V=float(k_out * dg.demodulator.baseband(V_s, -1j * R_I)),
                          locked=bool(lf.u_min_V <= v_tune <= lf.u_max_V))


def pll_scale_factor_V_per_dps(pll: PLLDrive) -> float:
    """Rate output per deg/s of the locked PLL drive (from two steady states).

    Parameters
    ----------
    pll : PLLDrive

    Returns
    -------
    float
        V/(deg/s).
    """
    d = np.deg2rad(1.0)
    return (pll_steady_state(pll, d).rate_V - pll_steady_state(pll, -d).rate_V) / 2.0
