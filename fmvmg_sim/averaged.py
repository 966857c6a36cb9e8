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

from .diagram import Diagram

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
    n = dg.vdac_V / np.sqrt(vx ** 2 + vps ** 2) if dg.carrier_mode == "normalized" else np.ones_like(th)
    c, s = np.cos(dg.phase_trim_rad), np.sin(dg.phase_trim_rad)
    carrier = _fundamental(n * vps)
    ref_i = _fundamental(n * (c * vps - s * vx))
    ref_q = _fundamental(n * (c * vx + s * vps))
    return carrier, ref_i, ref_q


def drive_loop_phase(dg: Diagram, omega: float) -> float:
    """Phase (rad) of the open drive loop x -> F_x -> x at ``omega``; zero where it oscillates.

    Parameters
    ----------
    dg : Diagram
    omega : float

    Returns
    -------
    float
    """
    r = dg.resonator
    Zd = r.k_drive_N_per_m - r.m_drive_kg * omega ** 2 + 1j * omega * r.c_drive_N_s_per_m
    Hx = dg.drive_chain_response(omega)
    V_x = Hx
    V_ps = Hx * dg.phase_shifter_response(omega)
    carrier, _, _ = carrier_phasors(dg, V_x, V_ps)
    return float(np.angle(carrier / Zd))


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


def oscillation_frequency(dg: Diagram) -> float:
    """Angular frequency at which the drive loop phase is zero.

    Parameters
    ----------
    dg : Diagram

    Returns
    -------
    float
        rad/s.
    """
    w0 = dg.omega_drive_rad_s
    span = max(20.0 / dg.resonator.q_drive, 1e-4)
    return float(brentq(lambda w: drive_loop_phase(dg, w), w0 * (1 - span), w0 * (1 + span), xtol=1e-9, rtol=1e-15))


def steady_state(dg: Diagram, rate_rad_s: float = 0.0, vref_V: float | None = None) -> SteadyState:
    """The periodic steady state of the closed loop at ``rate_rad_s``.

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
    r = dg.resonator
    w = oscillation_frequency(dg)
    Hx = dg.drive_chain_response(w)
    Hps = dg.phase_shifter_response(w)
    vps_amp = (vref - dg.rectifier.offset_V) / dg.rectifier.describing_gain()
    A = vps_amp / abs(Hx * Hps)
    # the phase reference is the drive displacement: X real positive
    X = complex(A)
    V_x, V_ps = Hx * X, Hx * Hps * X
    carrier, R_I, R_Q = carrier_phasors(dg, V_x, V_ps)
    # full two-mode response to the drive force: (i w I - A) z = B F
    Amat = r.state_matrix(rate_rad_s)
    M = 1j * w * np.eye(4) - Amat
    # F_x such that the drive displacement equals X: solve with unit force, scale
    z1 = np.linalg.solve(M, np.array([0, 1 / r.m_drive_kg, 0, 0], dtype=complex))
    F = X / z1[0]
    z = z1 * F
    Y = z[2]
    k_lin = dg.comb_drive.linear_coef_N_per_V
    V_ac = F / k_lin
    g0 = abs(V_ac) / abs(V_ps)
    u0 = abs(V_ac) / (dg.modulator.k_per_V * abs(carrier))
    sp = dg.sense_pickoff
    V_s = dg.sense_amps_response(w) * (sp.gain_V_per_m * Y + sp.c_feedthrough_F / sp.c_feedback_F * V_ac)
    k_out = dg.output_lpf.gain
    rate_V = k_out * dg.demodulator.baseband(V_s, R_I)
    quad_V = k_out * dg.demodulator.baseband(V_s, R_Q)
    return SteadyState(omega_rad_s=w, f_Hz=w / (2 * np.pi), amplitude_m=A, v_ps_amplitude_V=vps_amp,
                       agc_effort_V=float(u0), modulator_gain=float(g0), rate_V=float(rate_V),
                       quadrature_V=float(quad_V), loop_phase_error_rad=loop_phase_error(dg),
                       X=X, Y=complex(Y), V_s=complex(V_s), R_I=R_I, R_Q=R_Q)


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

    ``SF = lambda (K_sy / K_dx) (pi/2) Vref G_dem / (2 dw) cos(phi)`` per rad/s, with
    ``K_dx = |H_dx H_ps|`` (V/m to the rectifier), ``K_sy`` the sense pickoff and
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
    k_dx = abs(dg.drive_chain_response(w) * dg.phase_shifter_response(w)) * dg.rectifier.gain
    k_sy = abs(dg.sense_pickoff.gain_V_per_m * dg.sense_amps_response(w))
    lam = dg.resonator.angular_gain
    dw = 2 * np.pi * dg.resonator.f_sense_Hz - w
    g_dem = dg.output_lpf.gain * dg.demodulator.k_per_V * abs(ss.R_I)
    ws = 2 * np.pi * dg.resonator.f_sense_Hz
    phi = np.arctan2(ws * w / dg.resonator.q_sense, ws ** 2 - w ** 2)  # mechanical sense phase
    sf_rad = lam * (k_sy / k_dx) * (np.pi / 2) * (dg.vref_V - dg.rectifier.offset_V) * g_dem / (2 * dw) * np.cos(phi)
    return float(sf_rad * np.pi / 180.0)
