"""Phasor (averaged) analysis of the diagram: the steady state both engines must reach.

At a fixed temperature and rate every signal is a sinusoid at the loop's oscillation
frequency; each block acts through its envelope face (complex gain, describing
function, baseband product). This module finds that steady state: the oscillation
frequency (where the loop phase is zero), the drive amplitude the AGC sets, the AGC
effort, and the demodulated rate and quadrature outputs. The envelope engine
(:mod:`fmvmg_sim.envelope`) adds the dynamics around it; the tests compare the
carrier engine with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .diagram import Diagram, build_diagram

_NFFT = 256


@dataclass
class SteadyState:
    """The loop's periodic steady state at one operating point and rate.

    Attributes
    ----------
    omega_rad_s, f_Hz : float
        Oscillation frequency.
    amplitude_m : float
        Drive amplitude |X|.
    v_ps_amplitude_V : float
        Amplitude of the phase-shifted pickoff signal.
    agc_effort_V : float
        PI output u0.
    modulator_gain : float
        g0 = v_ac amplitude / v_ps amplitude.
    rate_V, quadrature_V : float
        Demodulated outputs (after the output low-pass DC gain).
    loop_phase_error_rad : float
        Electronic phase error delta of the drive loop at the natural frequency
        (predicts ``f = f_d (1 + tan(delta) / (2 Q_d))``).
    X, Y, V_s, R_I, R_Q : complex
        Phasors of drive and sense displacement, sense-chain output and the references.
    agc_saturated : bool
        The effort the set-point needs is beyond the PI's output limits: the PI sits at the limit
        and the amplitude settles where that effort holds it (below the set-point).
    """

    omega_rad_s: float
    f_Hz: float
    amplitude_m: float
    v_ps_amplitude_V: float
    agc_effort_V: float
    modulator_gain: float
    rate_V: float
    quadrature_V: float
    loop_phase_error_rad: float
    X: complex
    Y: complex
    V_s: complex
    R_I: complex
    R_Q: complex
    agc_saturated: bool = False


def _fundamental(samples: np.ndarray) -> complex:
    """Phasor of the fundamental of one period sampled at _NFFT points (x = Re(P e^{i theta}))."""
    return complex(2.0 * np.fft.fft(samples)[1] / len(samples))


def carrier_phasors(dg: Diagram, V_x: complex, V_ps: complex) -> tuple[complex, complex, complex]:
    """Fundamentals of the carrier and of the I and Q demodulation references.

    For the 'normalized' carrier the signals are ``Vdac * s(t) / sqrt(v_x^2 + v_ps^2)``,
    which is not exactly sinusoidal when v_x and v_ps are not in exact quadrature; the
    fundamental is taken numerically over one period.

    Parameters
    ----------
    dg : Diagram
    V_x, V_ps : complex
        Phasors of the drive pickoff and the phase-shifted signal.

    Returns
    -------
    tuple of complex
        (carrier, reference I, reference Q)
    """
    th = 2 * np.pi * np.arange(_NFFT) / _NFFT
    e = np.exp(1j * th)
    vx, vps = np.real(V_x * e), np.real(V_ps * e)
    n = dg.amplitude_loop.carrier_gain(vx, vps)
    c, s = np.cos(dg.phase_trim_rad), np.sin(dg.phase_trim_rad)
    carrier = _fundamental(n * vps)
    ref_i = _fundamental(n * (c * vps - s * vx))
    ref_q = _fundamental(n * (c * vx + s * vps))
    return carrier, ref_i, ref_q


def drive_response(dg: Diagram, omega: float, rate_rad_s: float = 0.0, k_extra_N_per_m: float = 0.0) -> np.ndarray:
    """Resonator state phasors (x, x', y, y') per newton of drive force at ``omega``.

    The full two-mode model, so the sense mode's back-action on the drive (through the
    quadrature and damping coupling and the Coriolis force) is included; it matters when
    the mode split is small (config B, the dual-mass gyro).

    Parameters
    ----------
    dg : Diagram
    omega : float
    rate_rad_s : float, optional
    k_extra_N_per_m : float, optional
        Extra drive stiffness (the Duffing term's describing function at the amplitude).

    Returns
    -------
    ndarray of complex, shape (4,)
    """
    r = dg.resonator
    M = 1j * omega * np.eye(4) - r.state_matrix(rate_rad_s, k_extra_N_per_m)
    return np.linalg.solve(M, np.array([0, 1 / r.m_drive_kg, 0, 0], dtype=complex))


def drive_loop_phase(dg: Diagram, omega: float, rate_rad_s: float = 0.0) -> float:
    """Phase (rad) of the open drive loop x -> F_x -> x at ``omega``; zero where it oscillates.

    Parameters
    ----------
    dg : Diagram
    omega : float
    rate_rad_s : float, optional

    Returns
    -------
    float
    """
    Hx = dg.drive_chain_response(omega)
    carrier, _, _ = carrier_phasors(dg, Hx, Hx * dg.phase_shifter_response(omega))
    return float(np.angle(carrier * drive_response(dg, omega, rate_rad_s)[0]))


def loop_phase_error(dg: Diagram) -> float:
    """Electronic phase error delta of the drive loop at the drive-mode natural frequency.

    ``delta = arg(carrier / v_x-phasor of x) - 90 deg``: positive means the force leads
    the velocity, and the loop then oscillates above resonance.

    Parameters
    ----------
    dg : Diagram

    Returns
    -------
    float
    """
    w = dg.omega_drive_rad_s
    Hx = dg.drive_chain_response(w)
    carrier, _, _ = carrier_phasors(dg, Hx, Hx * dg.phase_shifter_response(w))
    return float(np.angle(carrier) - np.pi / 2)


def ripple_feedback(dg: Diagram, omega: float, V_ps: complex) -> complex:
    """2-omega phasor of the PI output caused by the rectifier ripple that leaks through the LPF (4).

    ``|cos| = 2/pi + (4/(3 pi)) cos(2 theta) - ...``: the ripple passes the amplitude LPF and
    the PI; multiplied by the carrier in the modulator it adds ``U2 conj(C) / 2`` to the
    drive force's fundamental. Negligible for the 30.7 kHz FMVMG (1e-4 of the effort), about
    1 % for the 3.5 kHz dual-mass gyro with the same 200 Hz filter.

    Parameters
    ----------
    dg : Diagram
    omega : float
        Oscillation frequency.
    V_ps : complex
        Phasor of the phase-shifted pickoff (the rectifier input).

    Returns
    -------
    complex
    """
    return dg.amplitude_loop.effort_ripple(omega, V_ps)


def _chain(dg: Diagram, omega: float) -> tuple:
    """The drive chain's and the phase shifter's responses at ``omega`` (both :func:`_amplitude` and
    :func:`_loop` need them at every frequency the root search tries)."""
    return dg.drive_chain_response(omega), dg.phase_shifter_response(omega)


def _loop(dg: Diagram, omega: float, A: float, rate_rad_s: float, chain: tuple | None = None,
          ripple: bool = True):
    """Complex AGC effort that holds a drive amplitude ``A`` at ``omega`` (real at the oscillation frequency);
    ``chain`` is :func:`_chain` at ``omega`` when already evaluated; ``ripple=False`` when the PI is clamped
    (the rectifier ripple does not pass a clamped output)."""
    Hx, Hps = _chain(dg, omega) if chain is None else chain
    V_x, V_ps = Hx * A, Hx * Hps * A
    carrier, R_I, R_Q = carrier_phasors(dg, V_x, V_ps)
    z1 = drive_response(dg, omega, rate_rad_s, dg.resonator.duffing_stiffness(A))
    F = A / z1[0]
    V_ac = F / dg.comb_drive.linear_coef_N_per_V
    U2 = ripple_feedback(dg, omega, V_ps) if ripple else 0.0
    u = dg.amplitude_loop.effort_for(V_ac, carrier, U2)
    return u, dict(V_x=V_x, V_ps=V_ps, carrier=carrier, R_I=R_I, R_Q=R_Q, z1=z1, F=F, V_ac=V_ac)


def _amplitude(dg: Diagram, omega: float, vref: float, chain: tuple | None = None) -> float:
    """The drive amplitude the loop holds at ``omega`` for the set-point ``vref``."""
    Hx, Hps = _chain(dg, omega) if chain is None else chain
    return dg.amplitude_loop.held_drive_amplitude_m(Hx * Hps, vref)


def oscillation_frequency(dg: Diagram, rate_rad_s: float = 0.0, vref_V: float | None = None) -> float:
    """Angular frequency at which the closed drive loop oscillates.

    Where the loop's phase balances: the AGC effort that holds the amplitude is real.
    Includes the sense mode's back-action on the drive and the rectifier-ripple feedback.

    Parameters
    ----------
    dg : Diagram
    rate_rad_s : float, optional
    vref_V : float, optional

    Returns
    -------
    float
        rad/s.
    """
    vref = dg.vref_V if vref_V is None else vref_V

    def imag_u(w):
        chain = _chain(dg, w)
        return _loop(dg, w, _amplitude(dg, w, vref, chain), rate_rad_s, chain)[0].imag

    return _phase_balance(dg, imag_u)


def _phase_balance(dg: Diagram, imag_u) -> float:
    """The frequency near the drive mode where ``imag_u`` (the AGC effort's imaginary part) vanishes."""
    w0 = dg.omega_drive_rad_s
    span = max(20.0 / dg.resonator.q_drive, 1e-4)
    return float(brentq(imag_u, w0 * (1 - span), w0 * (1 + span), xtol=1e-9, rtol=1e-15))


def _clamped(dg: Diagram, rate_rad_s: float, u_V: float, A_set: float) -> tuple[float, float]:
    """Frequency and amplitude at which the loop holds itself with the PI output fixed at ``u_V``.

    The phase balances where the effort's imaginary part vanishes; the amplitude where its real part is
    ``u_V`` (proportional to the amplitude for a linear resonator, so one bracket around the set-point's
    amplitude scaled by the effort ratio holds it).
    """
    def freq(A):
        return _phase_balance(dg, lambda w: _loop(dg, w, A, rate_rad_s, ripple=False)[0].imag)

    def excess(A):
        return _loop(dg, freq(A), A, rate_rad_s, ripple=False)[0].real - u_V

    u_set = _loop(dg, freq(A_set), A_set, rate_rad_s, ripple=False)[0].real
    guess = A_set * u_V / u_set
    lo, hi = 0.5 * guess, 2.0 * guess
    while excess(lo) > 0 and lo > 1e-6 * guess:
        lo *= 0.5
    while excess(hi) < 0 and hi < 1e6 * guess:
        hi *= 2.0
    A = float(brentq(excess, lo, hi, xtol=1e-18, rtol=1e-13))
    return freq(A), A


def steady_state(dg: Diagram, rate_rad_s: float = 0.0, vref_V: float | None = None) -> SteadyState:
    """The periodic steady state of the closed loop at ``rate_rad_s``.

    Where holding the set-point would need an AGC effort beyond the PI's output limits, the PI
    sits at the limit (its integrator held by the anti-windup) and the amplitude settles where
    that effort holds it: ``agc_saturated`` is set and the amplitude is below the set-point.

    Parameters
    ----------
    dg : Diagram
    rate_rad_s : float, optional
        Constant input rate.
    vref_V : float, optional
        Amplitude set-point (defaults to the diagram's Vref).

    Returns
    -------
    SteadyState
    """
    vref = dg.vref_V if vref_V is None else vref_V
    w = oscillation_frequency(dg, rate_rad_s, vref)
    chain = _chain(dg, w)
    A = _amplitude(dg, w, vref, chain)
    u, p = _loop(dg, w, A, rate_rad_s, chain)
    u_lim = dg.pi.u_max_V if u.real > dg.pi.u_max_V else (dg.pi.u_min_V if u.real < dg.pi.u_min_V else None)
    saturated = u_lim is not None and u_lim > 0  # a limit at or below zero cannot hold an oscillation
    if saturated:
        w, A = _clamped(dg, rate_rad_s, u_lim, A)
        u, p = _loop(dg, w, A, rate_rad_s, ripple=False)
        u = complex(u_lim, 0.0)
    X = complex(A)  # the phase reference is the drive displacement
    Y = p["z1"][2] * p["F"]
    ripple = 0.0 if saturated else ripple_feedback(dg, w, p["V_ps"])
    V_ac = dg.amplitude_loop.drive_phasor(u.real, p["carrier"], ripple)
    sp = dg.sense_pickoff
    V_s = dg.sense_amps_response(w) * (sp.gain_V_per_m * Y + sp.c_feedthrough_F / sp.c_feedback_F * V_ac)
    k_out = dg.output_lpf.gain
    rate_V = k_out * dg.demodulator.baseband(V_s, p["R_I"])
    quad_V = k_out * dg.demodulator.baseband(V_s, p["R_Q"])
    if dg.sense_loop is not None:  # closed-loop sense (fmvmg_sim.rebalance): the loops null their channels
        loop = dg.sense_loop.steady_outputs(dg, w, A, V_s, Y, p["carrier"], p["R_I"], p["R_Q"])
        V_s, Y, rate_V, quad_V = loop["V_s"], loop["Y"], loop["rate_V"], loop["quadrature_V"]
    return SteadyState(omega_rad_s=w, f_Hz=w / (2 * np.pi), amplitude_m=A, v_ps_amplitude_V=abs(p["V_ps"]),
                       agc_effort_V=float(u.real), modulator_gain=float(abs(p["V_ac"]) / abs(p["V_ps"])),
                       rate_V=float(rate_V), quadrature_V=float(quad_V), loop_phase_error_rad=loop_phase_error(dg),
                       X=X, Y=complex(Y), V_s=complex(V_s), R_I=p["R_I"], R_Q=p["R_Q"], agc_saturated=saturated)


def scale_factor_V_per_dps(dg: Diagram) -> float:
    """Rate output per deg/s at this operating point (from two steady states).

    Parameters
    ----------
    dg : Diagram

    Returns
    -------
    float
        V/(deg/s).
    """
    d = np.deg2rad(1.0)
    return (steady_state(dg, d).rate_V - steady_state(dg, -d).rate_V) / 2.0


def zero_rate_bias_dps(dg: Diagram, nominal_sf_V_per_dps: float | None = None) -> float:
    """Zero-rate output in deg/s (divided by ``nominal_sf`` or the local scale factor).

    Parameters
    ----------
    dg : Diagram
    nominal_sf_V_per_dps : float, optional

    Returns
    -------
    float
    """
    sf = nominal_sf_V_per_dps or scale_factor_V_per_dps(dg)
    return steady_state(dg, 0.0).rate_V / sf


def closed_form_scale_factor_V_per_dps(dg: Diagram) -> float:
    """The physics brief's closed form (section 2) of the scale factor.

    ``SF = lambda (K_sy / K_dx) (pi/2) Vref G_dem / (2 dw) cos(phi)`` per rad/s, written as
    ``lambda K_sy A_d G_dem / (2 dw) cos(phi)`` with ``A_d = (Vref - V_off) / (G_rect K_dx)`` the drive
    amplitude the AGC holds (``K_dx = |H_dx H_ps|`` the V/m to the rectifier, ``G_rect = 2 G_r / pi`` its
    describing gain, ``V_off`` its offset), ``K_sy`` the sense pickoff and
    amplifier gain (V/m), ``G_dem = G_out K_m Vdac``, ``dw`` the mode split in rad/s and
    ``phi`` the mechanical sense phase (the electronic mismatch is trimmed out). It neglects the sense damping and
    ``omega_s^2 - omega^2 ~ 2 omega dw``, so it agrees with :func:`scale_factor_V_per_dps`
    to a few parts per thousand.

    Parameters
    ----------
    dg : Diagram

    Returns
    -------
    float
        V/(deg/s).
    """
    ss = steady_state(dg)
    w = ss.omega_rad_s
    amplitude_m = _amplitude(dg, w, dg.vref_V)
    k_sy = abs(dg.sense_pickoff.gain_V_per_m * dg.sense_amps_response(w))
    lam = dg.resonator.angular_gain
    dw = 2 * np.pi * dg.resonator.f_sense_Hz - w
    g_dem = dg.output_lpf.gain * dg.demodulator.k_per_V * abs(ss.R_I)
    ws = 2 * np.pi * dg.resonator.f_sense_Hz
    phi = np.arctan2(ws * w / dg.resonator.q_sense, ws ** 2 - w ** 2)  # mechanical sense phase
    sf_rad = lam * k_sy * amplitude_m * g_dem / (2 * dw) * np.cos(phi)
    return float(sf_rad * np.pi / 180.0)


def bias_temperature_coefficients_dph_per_K(device, temperature_C: float | None = None,
                                            step_K: float = 0.5) -> dict:
    """Zero-rate bias temperature coefficients of ``device``: together, through the die, through the board.

    Central differences of the averaged steady state's bias (divided by the nominal scale factor at the
    reference temperature, as the records are): ``total`` with die and board at one temperature (a slow
    oven), ``die`` with the board held (the MEMS laws), ``board`` with the die held (the electronics
    laws). ``total = die + board`` to first order.

    Parameters
    ----------
    device : fmvmg_sim.device.Device
    temperature_C : float, optional
        Where to take the derivatives (default: the device's reference temperature).
    step_K : float, optional
        Half-width of the central differences.

    Returns
    -------
    dict
        ``total``, ``die`` and ``board`` in deg/h per K.
    """
    T = device.reference_temperature_C if temperature_C is None else float(temperature_C)
    sf = device.nominal_scale_factor_V_per_dps

    def bias_dph(die_C, board_C):
        return steady_state(build_diagram(device, die_C, board_C=board_C)).rate_V / sf * 3600.0

    lo, hi = T - step_K, T + step_K
    return {"total": (bias_dph(hi, hi) - bias_dph(lo, lo)) / (2 * step_K),
            "die": (bias_dph(hi, T) - bias_dph(lo, T)) / (2 * step_K),
            "board": (bias_dph(T, hi) - bias_dph(T, lo)) / (2 * step_K)}
