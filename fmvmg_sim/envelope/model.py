"""The averaged model of the diagram at one operating point, discretised exactly for step ``h``.

Derived from the same blocks as the carrier engine (their envelope faces), not a copy:

* drive amplitude A (m), relative to the loop's oscillation frequency ``w`` (the zero of the
  loop phase, :func:`fmvmg_sim.averaged.oscillation_frequency`)::

      A' = Re[(u f_c - Z_d A) / D_d],   theta' = Im[(u f_c - Z_d A) / D_d] / A
      Z_d = k_d - m_d w^2 + i w c_d,  D_d = 2 i w m_d + c_d,  f_c = K_comb K_mod C  (carrier phasor C)

* rectifier + LPF (4): the LPF driven by the describing function ``(2/pi) G_r |H_dx H_ps| A``;
* comparator and PI: ``u = Kp (Vref - r) + Ki I``, clamped with the integrator held;
* sense envelope Y (complex, in the drive's phase frame)::

      Y' = (F_y - Z_s Y) / D_s,  F_y = (-(2 m_c W + c_q) i w - k_q) A + F_noise

* sense chain ``V_s = H_se (K_sy Y + (C_ft/C_f) K_mod u C) + noise`` and the output LPF
  applied to Re V_s and Im V_s; demodulation (13) with the reference phasors R_I, R_Q
  (rotated by the demodulation-phase flicker) commutes with the LPF because the
  references vary slowly: ``rate_V = G_out K_m Re(LPF(V_s) conj(R_I)) / 2``.

The drive loop is linear when the PI is not saturated; it is discretised exactly in
closed loop (and, for saturation, with ``u`` as a held input). The sense part is
discretised exactly with first-order hold on its inputs ``A``, ``W A`` and ``u``. White
noises enter through their exact one-step covariance, so the step can be as long as an
output interval.
"""

from __future__ import annotations

import numpy as np

from ..averaged import carrier_phasors, steady_state
from ..carrier.discretize import foh, noise_factor, zoh
from ..carrier.layout import Layout
from ..diagram import Diagram
from ..errors import InputError

ND, NS = 5, 8  # drive states [A, s1, s2, I, J=int s1], sense [Yr, Yi, sr1, sr2, si1, si2, Jr, Ji]

PARAMS = Layout([
    ("Phi_d", (ND, ND)), ("Gd0", (ND,)), ("Gd1", (ND,)), ("Gdc", (ND,)), ("L_d", (ND, ND)),
    ("Phi_ds", (4, 4)), ("Gdsu", (4,)), ("Gdsc", (4,)),
    ("vref0", ()), ("kp", ()), ("ki", ()), ("u_min", ()), ("u_max", ()),
    ("Phi_s", (NS, NS)), ("Gs0", (NS, 3)), ("Gs1", (NS, 3)), ("L_s", (NS, NS)),
    ("R_I", (2,)), ("R_Q", (2,)), ("g_out", ()), ("h", ()),
    ("omega", ()), ("b_u", ()), ("b_A", ()),
])


def operating_params(dg: Diagram, h_s: float, noise_on: dict) -> dict:
    """Discretised averaged model at the diagram's operating point.

    Parameters
    ----------
    dg : Diagram
    h_s : float
        Envelope step.
    noise_on : dict
        Switches ``brownian`` and ``electronic``.

    Returns
    -------
    dict
        Fields of :data:`PARAMS`, plus ``steady`` (the :class:`~fmvmg_sim.averaged.SteadyState`).
    """
    if dg.carrier_mode != "normalized":
        raise InputError("the envelope engine models the 'normalized' carrier only; use --fidelity carrier",
                         "circuit.modulator.carrier")
    ss = steady_state(dg)
    w = ss.omega_rad_s
    r = dg.resonator
    Hx, Hps = dg.drive_chain_response(w), dg.phase_shifter_response(w)
    C0, _, _ = carrier_phasors(dg, Hx * ss.amplitude_m, Hx * Hps * ss.amplitude_m)  # carrier phasor (X real)
    Dd = 2j * w * r.m_drive_kg + r.c_drive_N_s_per_m
    Zd = r.k_drive_N_per_m - r.m_drive_kg * w ** 2 + 1j * w * r.c_drive_N_s_per_m
    fc = dg.comb_drive.linear_coef_N_per_V * dg.modulator.k_per_V * C0
    a_u, a_A = (fc / Dd).real, (Zd / Dd).real
    b_u, b_A = (fc / Dd).imag, (Zd / Dd).imag
    k_r = dg.rectifier.describing_gain() * abs(Hx * Hps)
    lp = dg.amplitude_lpf.linear_model()
    Al, Bl = np.asarray(lp.A), np.asarray(lp.B)[:, 0]
    kp, ki = dg.pi.kp, dg.pi.ki_per_s
    # --- drive, closed loop (unsaturated): x = [A, s1, s2, I, J], u = kp (vref - s1) + ki I, J' = s1
    M = np.zeros((ND, ND))
    M[0, 0], M[0, 1], M[0, 3] = -a_A, -a_u * kp, a_u * ki
    M[1:3, 0] = Bl * k_r
    M[1:3, 1:3] = Al
    M[3, 1] = -1.0
    M[4, 1] = 1.0
    Bv = np.array([a_u * kp, 0.0, 0.0, 1.0, 0.0])
    Bc = np.array([0.0, Bl[0] * dg.rectifier.offset_V, Bl[1] * dg.rectifier.offset_V, 0.0, 0.0])
    Phi_d, Gd0, Gd1 = foh(M, Bv[:, None], h_s)
    _, Gdc = zoh(M, Bc[:, None], h_s)
    # --- drive, saturated: x = [A, s1, s2, J], u held, integrator held
    keep = [0, 1, 2, 4]
    Ms = M[np.ix_(keep, keep)].copy()
    Ms[0, 1] = 0.0
    Phi_ds, Gdsu = zoh(Ms, np.array([[a_u], [0.0], [0.0], [0.0]]), h_s)
    _, Gdsc = zoh(Ms, Bc[keep, None], h_s)
    # drive noise: Brownian force on A, electronic noise on the rectified signal
    psd_fd, psd_fs = r.brownian_force_psd_N2_per_Hz()
    e_d = dg.noise["drive_input_V_per_sqrtHz"] * abs(dg.drive_amp.frequency_response(w)[0, 0] * Hps)
    q_A = (psd_fd * abs(1 / Dd) ** 2) if noise_on["brownian"] else 0.0  # two-sided intensity of A' noise
    q_r = (dg.rectifier.gain * e_d) ** 2 / 2 if noise_on["electronic"] else 0.0
    Gn = np.zeros((ND, 2))
    Gn[0, 0] = 1.0
    Gn[1:3, 1] = Bl
    L_d = noise_factor(M, Gn, np.diag([q_A, q_r]), h_s)
    # --- sense: x = [Yr, Yi, sr1, sr2, si1, si2, Jr, Ji]; inputs [A, W A, u]; J = integral of the LPF outputs
    Ds = 2j * w * r.m_sense_kg + r.c_sense_N_s_per_m
    Zs = r.k_sense_N_per_m - r.m_sense_kg * w ** 2 + 1j * w * r.c_sense_N_s_per_m
    a_Y = -Zs / Ds
    f_A = (-r.c_quad_N_s_per_m * 1j * w - r.k_quad_N_per_m) / Ds
    f_W = (-2 * r.m_coriolis_kg * 1j * w) / Ds
    Hse = dg.sense_amps_response(w)
    sp = dg.sense_pickoff
    kY = Hse * sp.gain_V_per_m
    kU = Hse * (sp.c_feedthrough_F / sp.c_feedback_F) * dg.modulator.k_per_V * C0
    ol = dg.output_lpf.linear_model()
    Ao, Bo = np.asarray(ol.A), np.asarray(ol.B)[:, 0] / dg.output_lpf.gain  # unit DC gain
    S = np.zeros((NS, NS))
    S[6, 2], S[7, 4] = 1.0, 1.0
    S[0:2, 0:2] = _cmat(a_Y)
    KY = _cmat(kY)  # [Re V; Im V] from [Yr; Yi]
    S[2:4, 2:4], S[4:6, 4:6] = Ao, Ao
    S[2:4, 0:2] = np.outer(Bo, KY[0])
    S[4:6, 0:2] = np.outer(Bo, KY[1])
    Bs = np.zeros((NS, 3))
    Bs[0:2, 0] = [f_A.real, f_A.imag]
    Bs[0:2, 1] = [f_W.real, f_W.imag]
    Bs[2:4, 2] = Bo * kU.real
    Bs[4:6, 2] = Bo * kU.imag
    Phi_s, Gs0, Gs1 = foh(S, Bs, h_s)
    # sense noise: complex Brownian force envelope (Re, Im two-sided intensity S_F each) and the
    # front-end voltage noise envelope (Re, Im two-sided intensity e^2 each)
    e_s = dg.noise["sense_input_V_per_sqrtHz"]
    Gs = np.zeros((NS, 4))
    Gs[0:2, 0:2] = _cmat(1 / Ds)
    Ke = _cmat(Hse)
    Gs[2:4, 2:4] = np.outer(Bo, Ke[0])
    Gs[4:6, 2:4] = np.outer(Bo, Ke[1])
    q_s = np.diag([psd_fs if noise_on["brownian"] else 0.0] * 2 + [e_s ** 2 if noise_on["electronic"] else 0.0] * 2)
    L_s = noise_factor(S, Gs, q_s, h_s)
    return dict(Phi_d=Phi_d, Gd0=Gd0[:, 0], Gd1=Gd1[:, 0], Gdc=Gdc[:, 0], L_d=L_d,
                Phi_ds=Phi_ds, Gdsu=Gdsu[:, 0], Gdsc=Gdsc[:, 0],
                vref0=dg.vref_V, kp=kp, ki=ki, u_min=dg.pi.u_min_V, u_max=dg.pi.u_max_V,
                Phi_s=Phi_s, Gs0=Gs0, Gs1=Gs1, L_s=L_s,
                R_I=[ss.R_I.real, ss.R_I.imag], R_Q=[ss.R_Q.real, ss.R_Q.imag],
                g_out=0.5 * dg.output_lpf.gain * dg.demodulator.k_per_V, h=h_s,
                omega=w, b_u=b_u, b_A=b_A, steady=ss,
                sense_steady=_sense_steady(a_Y, f_A, kY, kU, ss))


def _sense_steady(a_Y, f_A, kY, kU, ss) -> np.ndarray:
    """Sense states at the zero-rate steady state."""
    Y = -f_A * ss.amplitude_m / a_Y
    V = kY * Y + kU * ss.agc_effort_V
    return np.array([Y.real, Y.imag, V.real, 0.0, V.imag, 0.0, 0.0, 0.0])


def _cmat(z: complex) -> np.ndarray:
    """Real 2x2 matrix of multiplication by the complex number z."""
    return np.array([[z.real, -z.imag], [z.imag, z.real]])
