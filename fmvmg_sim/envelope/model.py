"""The averaged model of the diagram at one operating point, discretised exactly for step ``h``.

Derived from the same blocks as the carrier engine (their envelope faces), not a copy. In the
frame of the loop's oscillation frequency ``w`` (:func:`fmvmg_sim.averaged.oscillation_frequency`),
with the drive displacement as phase reference (``X = A`` real):

* drive amplitude::

      A' = Re[(u f_c + f_2 A - Z_d A + kappa Y) / D_d],  theta' = Im[...] / A
      Z_d = k_d - m_d w^2 + i w c_d,  D_d = 2 i w m_d + c_d,  f_c = K_comb K_mod C,
      kappa = -(k_q + i w c_q) + 2 i w m_c W   (the sense mode's back-action),
      f_2 A = K_comb K_mod U_2 conj(C) / 2     (rectifier ripple leaking through LPF (4) and the PI)

* rectifier + LPF (4): the LPF driven by the describing function ``(2/pi) G_r |H_dx H_ps| A``;
* comparator and PI: ``u = Kp (Vref - r) + Ki I``, clamped with the integrator held;
* sense envelope: ``Y' = (F_y - Z_s Y) / D_s``, ``F_y = (-(2 m_c W + c_q) i w - k_q) A + F_noise``;
* sense chain ``V_s = H_se (K_sy Y + (C_ft/C_f) V_ac) + noise`` and the output LPF applied to
  Re V_s and Im V_s; demodulation (13) with the reference phasors R_I, R_Q (rotated by the
  demodulation-phase flicker) commutes with the LPF because the references vary slowly:
  ``rate_V = G_out K_m Re(LPF(V_s) conj(R_I)) / 2``.

All of this is one linear system while the PI is not saturated; it is discretised exactly
(closed loop), and again with ``u`` as a held input for saturation. The rate enters through
first-order-hold inputs ``W A`` and ``W Y`` (A and Y held over the step). White noises enter
through their exact one-step covariance, so the step can be as long as an output interval.
Integrals ``J`` of the amplitude estimate and of the output LPF give integrate-and-dump outputs.

State: ``[A, s1, s2, I, J, Yr, Yi, Sr1, Sr2, Si1, Si2, Jr, Ji]``.
"""

from __future__ import annotations

import numpy as np

from ..averaged import carrier_phasors, ripple_feedback, steady_state
from ..carrier.discretize import batched_factor, foh, noise_covariance, zoh
from ..carrier.layout import Layout
from ..diagram import Diagram
from ..errors import InputError

N = 13
IA, IS1, IS2, II, IJ, IYR, IYI, ISR, ISR2, ISI, ISI2, IJR, IJI = range(N)
N_U = 7  # FOH inputs: [vref, W A, W Yr, W Yi, dkq A, dkq Yr, dkq Yi] (dkq: extra quadrature stiffness, N/m)
N_NOISE = N

PARAMS = Layout([
    ("Phi", (N, N)), ("G0", (N, N_U)), ("G1", (N, N_U)), ("Gc", (N,)),
    ("Phi_s", (N, N)), ("G0_s", (N, N_U)), ("G1_s", (N, N_U)), ("Gu_s", (N,)), ("Gc_s", (N,)),
    ("L", (N, N)),
    ("vref0", ()), ("kp", ()), ("ki", ()), ("u_min", ()), ("u_max", ()),
    ("R_I", (2,)), ("R_Q", (2,)), ("g_out", ()), ("h", ()),
    ("omega", ()), ("b_u", ()), ("b_A", ()), ("b_Y", (2,)), ("k_quad", ()),
])


def _cmat(z: complex) -> np.ndarray:
    """Real 2x2 matrix of multiplication by the complex number z."""
    return np.array([[z.real, -z.imag], [z.imag, z.real]])


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
        Fields of :data:`PARAMS`, plus ``steady`` (the :class:`~fmvmg_sim.averaged.SteadyState`)
        and ``x_steady`` (the state at the zero-rate steady state).
    """
    if dg.carrier_mode != "normalized":
        raise InputError("the envelope engine models the 'normalized' carrier only; use --fidelity carrier",
                         "circuit.modulator.carrier")
    ss = steady_state(dg)
    w = ss.omega_rad_s
    r = dg.resonator
    Hx, Hps = dg.drive_chain_response(w), dg.phase_shifter_response(w)
    A0 = ss.amplitude_m
    C0, _, _ = carrier_phasors(dg, Hx * A0, Hx * Hps * A0)
    kc = dg.comb_drive.linear_coef_N_per_V * dg.modulator.k_per_V
    Dd = 2j * w * r.m_drive_kg + r.c_drive_N_s_per_m
    kx = r.duffing_stiffness(A0)  # Duffing: describing-function stiffness at the amplitude
    Zd = r.k_drive_N_per_m + kx - r.m_drive_kg * w ** 2 + 1j * w * r.c_drive_N_s_per_m
    U2_per_A = ripple_feedback(dg, w, Hx * Hps * A0) / A0
    f2 = kc * 0.5 * U2_per_A * np.conj(C0)
    fu = kc * C0 / Dd                   # per unit u
    fA = (f2 - Zd) / Dd                 # per unit A
    kap0 = -(r.k_quad_N_per_m + 1j * w * r.c_quad_N_s_per_m) / Dd
    kapW = (2j * w * r.m_coriolis_kg) / Dd
    k_r = dg.rectifier.describing_gain() * abs(Hx * Hps)
    lp = dg.amplitude_lpf.linear_model()
    Al, Bl = np.asarray(lp.A), np.asarray(lp.B)[:, 0]
    kp, ki = dg.pi.kp, dg.pi.ki_per_s
    Ds = 2j * w * r.m_sense_kg + r.c_sense_N_s_per_m
    Zs = r.k_sense_N_per_m - r.m_sense_kg * w ** 2 + 1j * w * r.c_sense_N_s_per_m
    aY = -Zs / Ds
    sA = (-r.c_quad_N_s_per_m * 1j * w - r.k_quad_N_per_m) / Ds
    sW = (-2j * w * r.m_coriolis_kg) / Ds
    Hse = dg.sense_amps_response(w)
    sp = dg.sense_pickoff
    kY = Hse * sp.gain_V_per_m
    ft = Hse * (sp.c_feedthrough_F / sp.c_feedback_F) * dg.modulator.k_per_V
    kU, kU2 = ft * C0, ft * 0.5 * U2_per_A * np.conj(C0)  # V_s per unit u and per unit A (ripple part)
    ol = dg.output_lpf.linear_model()
    Ao, Bo = np.asarray(ol.A), np.asarray(ol.B)[:, 0] / dg.output_lpf.gain  # unit DC gain

    def system(closed: bool):
        M = np.zeros((N, N))
        Bu = np.zeros((N, N_U))     # FOH inputs
        Bc = np.zeros(N)            # constant input (rectifier offset)
        bu = np.zeros(N)            # held u (saturated)
        # u = kp (vref - s1) + ki I when closed; a held input otherwise
        u_row = np.zeros(N)
        u_vref = 0.0
        if closed:
            u_row[IS1], u_row[II], u_vref = -kp, ki, kp
        # drive amplitude
        M[IA, IA] = fA.real
        M[IA] += fu.real * u_row
        Bu[IA, 0] = fu.real * u_vref
        bu[IA] = fu.real
        M[IA, IYR], M[IA, IYI] = _cmat(kap0)[0]
        Bu[IA, 2], Bu[IA, 3] = _cmat(kapW)[0]
        Bu[IA, 5], Bu[IA, 6] = _cmat(-1.0 / Dd)[0]
        # amplitude estimate, integrator, its integral
        M[IS1:IS2 + 1, IA] = Bl * k_r
        M[IS1:IS2 + 1, IS1:IS2 + 1] = Al
        Bc[IS1:IS2 + 1] = Bl * dg.rectifier.offset_V
        if closed:
            M[II, IS1] = -1.0
            Bu[II, 0] = 1.0
        M[IJ, IS1] = 1.0
        # sense envelope
        M[IYR:IYI + 1, IYR:IYI + 1] = _cmat(aY)
        M[IYR:IYI + 1, IA] = [sA.real, sA.imag]
        Bu[IYR:IYI + 1, 1] = [sW.real, sW.imag]
        Bu[IYR:IYI + 1, 4] = [(-1.0 / Ds).real, (-1.0 / Ds).imag]
        # sense chain and output LPF on Re/Im of V_s = kY Y + kU u + kU2 A
        for comp, (i1, i2) in enumerate(((ISR, ISR2), (ISI, ISI2))):
            KY = _cmat(kY)[comp]
            rows = slice(i1, i2 + 1)
            M[rows, i1:i2 + 1] = Ao
            M[rows, IYR] += Bo * KY[0]
            M[rows, IYI] += Bo * KY[1]
            ku = (kU.real, kU.imag)[comp]
            M[rows, IA] += Bo * (kU2.real, kU2.imag)[comp]
            M[rows, :] += np.outer(Bo, ku * u_row)
            Bu[rows, 0] += Bo * ku * u_vref
            bu[rows] = Bo * ku
        M[IJR, ISR], M[IJI, ISI] = 1.0, 1.0
        return M, Bu, Bc, bu

    M, Bu, Bc, _ = system(True)
    Phi, G0, G1 = foh(M, Bu, h_s)
    _, Gc = zoh(M, Bc[:, None], h_s)
    Ms, Bus, Bcs, bus = system(False)
    Phi_s, G0_s, G1_s = foh(Ms, Bus, h_s)
    _, Gcu = zoh(Ms, np.column_stack([Bcs, bus]), h_s)
    # white noises: drive Brownian (in-phase part on A), electronic noise on the rectified signal,
    # sense Brownian force envelope (Re, Im) and sense front-end voltage envelope (Re, Im)
    psd_fd, psd_fs = r.brownian_force_psd_N2_per_Hz()
    e_d = dg.noise["drive_input_V_per_sqrtHz"] * abs(dg.drive_amp.frequency_response(w)[0, 0] * Hps)
    e_s = dg.noise["sense_input_V_per_sqrtHz"]
    br, el = noise_on["brownian"], noise_on["electronic"]
    Gn = np.zeros((N, 6))
    Gn[IA, 0] = 1.0
    Gn[IS1:IS2 + 1, 1] = Bl
    Gn[IYR:IYI + 1, 2:4] = _cmat(1 / Ds)
    for comp, (i1, i2) in enumerate(((ISR, ISR2), (ISI, ISI2))):
        Gn[i1:i2 + 1, 4:6] = np.outer(Bo, _cmat(Hse)[comp])
    q = np.array([psd_fd * abs(1 / Dd) ** 2 if br else 0.0, (dg.rectifier.gain * e_d) ** 2 / 2 if el else 0.0,
                  psd_fs if br else 0.0, psd_fs if br else 0.0, e_s ** 2 if el else 0.0, e_s ** 2 if el else 0.0])
    Q = noise_covariance(M, Gn, np.diag(q), h_s)
    L = batched_factor(Q[None])[0]
    # frequency: theta' = Im[(u f_c + f_A A + kappa Y)/D_d] / A
    x_ss = _steady_state_vector(ss, aY, sA, kY, kU, kU2, ki)
    return dict(Phi=Phi, G0=G0, G1=G1, Gc=Gc[:, 0], Phi_s=Phi_s, G0_s=G0_s, G1_s=G1_s, Gu_s=Gcu[:, 1],
                Gc_s=Gcu[:, 0], L=L, vref0=dg.vref_V, kp=kp, ki=ki, u_min=dg.pi.u_min_V, u_max=dg.pi.u_max_V,
                R_I=[ss.R_I.real, ss.R_I.imag], R_Q=[ss.R_Q.real, ss.R_Q.imag],
                g_out=0.5 * dg.output_lpf.gain * dg.demodulator.k_per_V, h=h_s,
                omega=w, b_u=fu.imag, b_A=fA.imag, b_Y=list(_cmat(kap0)[1]), k_quad=r.k_quad_N_per_m,
                steady=ss, x_steady=x_ss, Q=Q)


def _steady_state_vector(ss, aY, sA, kY, kU, kU2, ki) -> np.ndarray:
    """The state at the zero-rate steady state (integrals J at zero)."""
    x = np.zeros(N)
    A, u = ss.amplitude_m, ss.agc_effort_V
    Y = -sA * A / aY
    V = kY * Y + kU * u + kU2 * A
    x[IA], x[IS1], x[II] = A, 0.0, (u / ki if ki > 0 else 0.0)
    x[IYR], x[IYI] = Y.real, Y.imag
    x[ISR], x[ISI] = V.real, V.imag
    return x
