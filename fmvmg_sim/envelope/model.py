"""The averaged model of the diagram at one operating point, discretised exactly for step ``h``.

Derived from the same blocks as the carrier engine (their envelope faces), not a copy. In the
frame of the loop's oscillation frequency ``w`` (:func:`fmvmg_sim.averaged.oscillation_frequency`),
with the drive displacement as phase reference (``X = A`` real):

* drive amplitude::

      A' = Re[(rho u f_c + f_2 A - Z_d A + kappa Y) / D_d],  theta' = Im[...] / A
      Z_d = k_d - m_d w^2 + i w c_d,  D_d = 2 i w m_d + c_d,  f_c = K_comb K_mod C,
      kappa = -(k_q + i w c_q) + 2 i w m_c W   (the sense mode's back-action),
      f_2 A = K_comb K_mod U_2 conj(C) / 2     (rectifier ripple leaking through LPF (4) and the PI)

  (first order in the envelope: its amplitude response is within 1e-4 of the second-order
  mode's, see the tests); ``rho = min(1, A / A_floor)`` is the carrier normaliser's floor:
  below it the carrier shrinks with the pickoff (:attr:`fmvmg_sim.amplitude_loop.AmplitudeLoop.floor_V`);
* rectifier + LPF (4): the LPF driven by the describing function ``(2/pi) G_r |H_dx H_ps| A``;
* comparator and PI: ``u = Kp (Vref - r) + Ki I``, clamped, the integrator held while the error
  pushes further into the clamp (:meth:`blocks.PIController.clamp_state`); these rows are the
  amplitude loop's envelope face (:meth:`fmvmg_sim.amplitude_loop.AmplitudeLoop.envelope_rows`);
* sense mode: the resonator's exact envelope face (:meth:`blocks.TwoModeResonator.envelope_mode`),
  ``Y = Y_s + d F_y``, ``Y_s' = s_1 Y_s + r F_y``, ``F_y = -(2 m_c W + c_q) i w A - k_q A + F_noise``;
* sense chain ``V_s = H_se (K_sy Y + (C_ft/C_f) V_ac) + noise`` and the output LPF applied to
  Re V_s and Im V_s; demodulation (13) with the reference phasors R_I, R_Q (rotated by the
  demodulation-phase flicker) commutes with the LPF because the references vary slowly:
  ``rate_V = G_out K_m Re(LPF(V_s) conj(R_I)) / 2``.

All of this is one linear system in each of two pieces: the PI free (closed loop) and the PI
clamped (``u`` a held input). Each is discretised exactly for the step and for a sub-step
``h / N_SUB``; a step that crosses from one piece into another, or runs below the normaliser's
floor, is redone in sub-steps (:class:`fmvmg_sim.compiled.Refinement`). The rate enters through
first-order-hold inputs ``W A`` and ``W Y`` (A and Y held over the step). White noises enter
through their exact one-step covariance, so the step can be as long as an output interval.
Integrals ``J`` of the amplitude estimate and of the output LPF give integrate-and-dump outputs, and
with the integral ``K`` of the PI's integrator, the PI output's exact mean over a step.

State: ``[A, s1, s2, I, J, Yr, Yi, Sr1, Sr2, Si1, Si2, Jr, Ji, K]`` (``Y`` the sense mode's slow part).

A further clamped block (a force-to-rebalance PI, a PLL's loop filter) is one more dimension of
pieces: a piece per combination of free and clamped blocks, each the system with the clamped
blocks' outputs as held inputs, discretised at both levels (:data:`PIECES`, :func:`piece_field`);
the step picks the piece from each block's ``clamp_state`` at its start and flags a change at
its end, and the refinement needs nothing more.
"""

from __future__ import annotations

import numpy as np

from ..amplitude_loop import CONTROLLER_FIELDS
from ..averaged import carrier_phasors, ripple_feedback, steady_state
from ..numerics.discretize import batched_factor, foh, noise_covariance
from ..numerics.layout import Layout
from ..diagram import Diagram
from ..errors import InputError

N = 14
IA, IS1, IS2, II, IJ, IYR, IYI, ISR, ISR2, ISI, ISI2, IJR, IJI, IK = range(N)
N_U = 7  # FOH inputs: [vref, W A, W Yr, W Yi, dkq A, dkq Yr, dkq Yi] (dkq: extra quadrature stiffness, N/m)
#: Standard normals per step: one per state but the integral K, whose own share of the step's noise (the
#: integral of the integrator's noise within a step) is left out: K only makes the PI output's mean exact.
N_NOISE = N - 1
#: Sub-steps of a refined step (a crossing into or out of the PI's clamp, the normaliser's floor).
N_SUB = 32

#: The two pieces of the model, each discretised for the step and the sub-step: field names per piece.
_PIECE_FIELDS = (("Phi", (N, N)), ("G0", (N, N_U)), ("G1", (N, N_U)), ("Gc", (N,)), ("Gu", (N,)))
PIECES = ("free", "held")
LEVELS = ("step", "sub")


def piece_field(name: str, piece: str, level: str) -> str:
    """Parameter name of one discretisation field (``Phi``, ``G0``, ``G1``, ``Gc``, ``Gu``).

    Parameters
    ----------
    name : str
    piece : {"free", "held"}
    level : {"step", "sub"}

    Returns
    -------
    str
    """
    return f"{name}_{piece}_{level}"


PARAMS = Layout(
    [(piece_field(name, piece, level), shape) for level in LEVELS for piece in PIECES for name, shape in _PIECE_FIELDS]
    + [
        ("L", (N, N_NOISE)),
    ] + CONTROLLER_FIELDS + [  # the amplitude loop's set-point and PI (fmvmg_sim.amplitude_loop)
        ("R_I", (2,)), ("R_Q", (2,)), ("g_out", ()), ("h", ()),
        ("omega", ()), ("b_u", ()), ("b_A", ()), ("b_Y", (2,)), ("k_quad", ()),
        ("y_A", (2,)), ("a_floor", ()),
    ])


def _cmat(z: complex) -> np.ndarray:
    """Real 2x2 matrix of multiplication by the complex number z."""
    return np.array([[z.real, -z.imag], [z.imag, z.real]])


def _discretise(M: np.ndarray, Bu: np.ndarray, Bc: np.ndarray, bu: np.ndarray, h_s: float) -> dict:
    """Exact discretisation of ``x' = M x + Bu in(t) + Bc + bu u`` for step ``h_s``: ``in`` linear over
    the step (first-order hold), the constant and ``u`` held (one matrix exponential)."""
    Phi, G0, G1 = foh(M, np.column_stack([Bu, Bc, bu]), h_s)
    held = G0[:, N_U:] + G1[:, N_U:]  # a held input: both hold gains together
    return dict(Phi=Phi, G0=G0[:, :N_U], G1=G1[:, :N_U], Gc=held[:, 0], Gu=held[:, 1])


def operating_params(dg: Diagram, h_s: float, noise_on: dict, extension=None) -> dict:
    """Discretised averaged model at the diagram's operating point.

    Parameters
    ----------
    dg : Diagram
    h_s : float
        Envelope step.
    noise_on : dict
        Switches ``brownian`` and ``electronic``.
    extension : object, optional
        Further states coupled to the model (a closed sense loop,
        :class:`fmvmg_sim.envelope.rebalance.SenseLoopExtension`): its ``system`` extends each piece's
        matrices, its ``noise`` the noise gains and covariance, its ``steady`` the steady state.

    Returns
    -------
    dict
        Fields of :data:`PARAMS`, plus ``steady`` (the :class:`~fmvmg_sim.averaged.SteadyState`),
        ``x_steady`` (the state at the zero-rate steady state) and ``Q`` (the one-step noise covariance of
        the first :data:`N_NOISE` states).
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
    fA = (f2 - Zd) / Dd                 # per unit A, PI free (the ripple passes the PI)
    fA_held = -Zd / Dd                  # PI clamped: no ripple reaches the modulator
    kap0 = -(r.k_quad_N_per_m + 1j * w * r.c_quad_N_s_per_m) / Dd
    kapW = (2j * w * r.m_coriolis_kg) / Dd
    loop = dg.amplitude_loop.envelope_rows(Hx * Hps)
    k_r, Al, Bl, kp, ki = loop.sensor_gain, loop.A, loop.B, loop.kp, loop.ki
    # sense mode: Y = Y_s + d F_y, Y_s' = s1 Y_s + r F_y; F_y = fyA A + fyW (W A) - (dkq A) + F_noise
    s1, rs, ds = r.envelope_mode("sense", w)
    fyA = -r.c_quad_N_s_per_m * 1j * w - r.k_quad_N_per_m
    fyW = -2j * w * r.m_coriolis_kg
    Hse = dg.sense_amps_response(w)
    sp = dg.sense_pickoff
    kY = Hse * sp.gain_V_per_m
    ft = Hse * (sp.c_feedthrough_F / sp.c_feedback_F) * dg.modulator.k_per_V
    kU, kU2 = ft * C0, ft * 0.5 * U2_per_A * np.conj(C0)  # V_s per unit u and per unit A (ripple part)
    ol = dg.output_lpf.linear_model()
    Ao, Bo = np.asarray(ol.A), np.asarray(ol.B)[:, 0] / dg.output_lpf.gain  # unit DC gain
    # the physical Y per unit of A, of the inputs W A and dkq A, and of the sense force noise
    yA, yW, yK = ds * fyA, ds * fyW, -ds

    def system(free: bool):
        M = np.zeros((N, N))
        Bu = np.zeros((N, N_U))     # FOH inputs
        Bc = np.zeros(N)            # constant input (rectifier offset)
        bu = np.zeros(N)            # u as a held input
        # u = kp (vref - s1) + ki I when free; a held input when clamped
        u_row = np.zeros(N)
        u_vref = 0.0
        if free:
            u_row[IS1], u_row[II], u_vref = -kp, ki, kp
        # drive amplitude, with the sense mode's back-action kappa Y, Y = Y_s + yA A + yW (W A) + yK (dkq A)
        M[IA, IA] = (fA if free else fA_held).real + (kap0 * yA).real
        M[IA] += fu.real * u_row
        Bu[IA, 0] = fu.real * u_vref
        bu[IA] = fu.real
        M[IA, IYR], M[IA, IYI] = _cmat(kap0)[0]
        Bu[IA, 1] = (kap0 * yW).real
        Bu[IA, 4] = (kap0 * yK).real
        Bu[IA, 2], Bu[IA, 3] = _cmat(kapW)[0]
        Bu[IA, 5], Bu[IA, 6] = _cmat(-1.0 / Dd)[0]
        # amplitude estimate, integrator (it integrates the error in both pieces: clamped, the step
        # keeps or drops what it gathered, by the anti-windup rule), its integral
        M[IS1:IS2 + 1, IA] = Bl * k_r
        M[IS1:IS2 + 1, IS1:IS2 + 1] = Al
        Bc[IS1:IS2 + 1] = Bl * loop.offset_V
        M[II, IS1] = -1.0
        Bu[II, 0] = 1.0
        M[IJ, IS1] = 1.0
        # sense mode, slow part
        M[IYR:IYI + 1, IYR:IYI + 1] = _cmat(s1)
        M[IYR:IYI + 1, IA] = [(rs * fyA).real, (rs * fyA).imag]
        Bu[IYR:IYI + 1, 1] = [(rs * fyW).real, (rs * fyW).imag]
        Bu[IYR:IYI + 1, 4] = [-rs.real, -rs.imag]
        # sense chain and output LPF on Re/Im of V_s = kY Y + kU u + kU2 A
        for comp, (i1, i2) in enumerate(((ISR, ISR2), (ISI, ISI2))):
            KY = _cmat(kY)[comp]
            pick = (lambda z: z.real) if comp == 0 else (lambda z: z.imag)  # noqa: E731
            rows = slice(i1, i2 + 1)
            M[rows, i1:i2 + 1] = Ao
            M[rows, IYR] += Bo * KY[0]
            M[rows, IYI] += Bo * KY[1]
            M[rows, IA] += Bo * (pick(kY * yA) + (pick(kU2) if free else 0.0))
            Bu[rows, 1] += Bo * pick(kY * yW)
            Bu[rows, 4] += Bo * pick(kY * yK)
            ku = pick(kU)
            M[rows, :] += np.outer(Bo, ku * u_row)
            Bu[rows, 0] += Bo * ku * u_vref
            bu[rows] = Bo * ku
        M[IJR, ISR], M[IJI, ISI] = 1.0, 1.0
        M[IK, II] = 1.0
        return M, Bu, Bc, bu

    out = {}
    ctx = dict(dg=dg, ss=ss, w=w, A0=A0, C0=C0, Dd=Dd, kap0=kap0, rs=rs, ds=ds, kY=kY, Hse=Hse, Ao=Ao, Bo=Bo)
    for piece in PIECES:
        M, Bu, Bc, bu = system(piece == "free")
        if extension is not None:
            M, Bu, Bc, bu = extension.system(M, Bu, Bc, bu, ctx)
        if piece == "free":
            M_free, Bc_free = M, Bc
        for level, hl in (("step", h_s), ("sub", h_s / N_SUB)):
            for name, val in _discretise(M, Bu, Bc, bu, hl).items():
                out[piece_field(name, piece, level)] = val
    # white noises: drive Brownian (in-phase part on A), electronic noise on the rectified signal,
    # sense Brownian force (Re, Im; into the slow part and the feedthrough) and sense front-end voltage (Re, Im)
    psd_fd, psd_fs = r.brownian_force_psd_N2_per_Hz()
    e_d = dg.noise["drive_input_V_per_sqrtHz"] * abs(dg.drive_amp.frequency_response(w)[0, 0] * Hps)
    e_s = dg.noise["sense_input_V_per_sqrtHz"]
    br, el = noise_on["brownian"], noise_on["electronic"]
    Gn = np.zeros((N, 6))
    Gn[IA, 0] = 1.0
    Gn[IA, 2:4] = _cmat(kap0 * ds)[0]
    Gn[IS1:IS2 + 1, 1] = Bl
    Gn[IYR:IYI + 1, 2:4] = _cmat(rs)
    for comp, (i1, i2) in enumerate(((ISR, ISR2), (ISI, ISI2))):
        Gn[i1:i2 + 1, 2:4] = np.outer(Bo, _cmat(kY * ds)[comp])
        Gn[i1:i2 + 1, 4:6] = np.outer(Bo, _cmat(Hse)[comp])
    q = np.array([psd_fd * abs(1 / Dd) ** 2 if br else 0.0, (dg.rectifier.gain * e_d) ** 2 / 2 if el else 0.0,
                  psd_fs if br else 0.0, psd_fs if br else 0.0, e_s ** 2 if el else 0.0, e_s ** 2 if el else 0.0])
    if extension is None:
        Q = noise_covariance(M_free, Gn, np.diag(q), h_s)[:N_NOISE, :N_NOISE]
        L = noise_factor(Q)
    else:
        Q, L = extension.noise(M_free, Gn, q, h_s, ctx)
    # the carrier normaliser's floor as a drive amplitude: below it the carrier is (Vdac / floor) v_ps
    a_floor = dg.amplitude_loop.floor_drive_amplitude_m(C0, Hx * Hps)
    x_ss, _ = steady_vector(dg)
    if extension is not None:
        x_ss = extension.steady(x_ss, ctx)
    # frequency: theta' = Im[(u f_c + f_A A + kappa Y)/D_d]
    out.update(L=L, **dg.amplitude_loop.controller_params(),
               R_I=[ss.R_I.real, ss.R_I.imag], R_Q=[ss.R_Q.real, ss.R_Q.imag],
               g_out=0.5 * dg.output_lpf.gain * dg.demodulator.k_per_V, h=h_s,
               omega=w, b_u=fu.imag, b_A=fA.imag, b_Y=list(_cmat(kap0)[1]), k_quad=r.k_quad_N_per_m,
               y_A=[yA.real, yA.imag], a_floor=a_floor, steady=ss, x_steady=x_ss, Q=Q)
    return out


def noise_factor(Q: np.ndarray) -> np.ndarray:
    """The step's noise factor from the covariance of the first :data:`N_NOISE` states (stacked or not):
    ``L L^T = Q``, with a zero row for K.

    Parameters
    ----------
    Q : ndarray, shape (..., N_NOISE, N_NOISE)

    Returns
    -------
    ndarray, shape (..., N, N_NOISE)
    """
    Q = np.asarray(Q)
    Lq = batched_factor(Q.reshape(-1, N_NOISE, N_NOISE))
    L = np.zeros((len(Lq), N, N_NOISE))
    L[:, :N_NOISE] = Lq
    return L.reshape(Q.shape[:-2] + (N, N_NOISE))


def steady_vector(dg: Diagram, rate_rad_s: float = 0.0, vref_factor: float = 1.0) -> tuple[np.ndarray, object]:
    """The model state on the averaged steady state (integrals J at zero).

    Parameters
    ----------
    dg : Diagram
    rate_rad_s : float, optional
        Constant input rate.
    vref_factor : float, optional
        Set-point as a multiple of Vref.

    Returns
    -------
    tuple
        The state (:data:`N` values) and the :class:`~fmvmg_sim.averaged.SteadyState`.
    """
    ss = steady_state(dg, rate_rad_s, dg.vref_V * vref_factor)
    r = dg.resonator
    w = ss.omega_rad_s
    _, _, ds = r.envelope_mode("sense", w)
    A = ss.amplitude_m
    F = (-r.c_quad_N_s_per_m * 1j * w - r.k_quad_N_per_m - 2j * w * r.m_coriolis_kg * rate_rad_s) * A
    Ys = ss.Y - ds * F  # the slow part: the steady sense phasor less the feedthrough
    x = np.zeros(N)
    x[IA] = A
    loop = dg.amplitude_loop
    x[IS1] = loop.detector_level_V(ss.v_ps_amplitude_V)
    x[II] = loop.integrator_state(min(ss.agc_effort_V, dg.pi.u_max_V) if ss.agc_saturated else ss.agc_effort_V)
    x[IYR], x[IYI] = Ys.real, Ys.imag
    x[ISR], x[ISI] = ss.V_s.real, ss.V_s.imag
    return x, ss
