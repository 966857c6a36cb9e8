"""Numbers for the PLL drive's carrier step: the PLL-driven diagram at an operating point, discretised exactly."""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from ..diagram import CORE_INPUTS, CORE_OUTPUTS
from ..numerics.discretize import expm_derivative, zoh
from ..pll_drive import PLLDrive, pll_steady_state
from .plan import OperatingPlan, _resonator_direction, noise_sigmas
from .pll_step import PARAMS, STATE

#: Rotation generator of the oscillator's (cos, sin) pair per rad/s.
_ROT = np.array([[0.0, -1.0], [1.0, 0.0]])


def oscillator_input(A: np.ndarray, b: np.ndarray, omega: float, h_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Response over a step to ``b cos(theta0 + omega t)``: the maps of ``(cos theta0, sin theta0)`` and their derivative.

    The top-right block of ``exp([[A, b e1'], [0, omega R]] h)`` (``R`` the rotation generator), and its
    derivative in ``omega`` (Van Loan).

    Parameters
    ----------
    A : ndarray, shape (n, n)
    b : ndarray, shape (n,)
    omega : float
        The oscillator's angular frequency (rad/s).
    h_s : float

    Returns
    -------
    tuple of ndarray
        ``G`` and ``dG/domega``, each of shape (n, 2).
    """
    n = A.shape[0]
    M = np.zeros((n + 2, n + 2))
    M[:n, :n], M[:n, n] = A, b
    M[n:, n:] = omega * _ROT
    dM = np.zeros_like(M)
    dM[n:, n:] = _ROT
    return expm(M * h_s)[:n, n:], expm_derivative(M, dM, h_s)[:n, n:]


def pll_plan_common(pll: PLLDrive, h_s: float, noise_on: dict | None, scale: np.ndarray | None, layout) -> tuple:
    """What the PLL drive's carrier and envelope plans share: the scaled core, the filters, gains and trims.

    Parameters
    ----------
    pll : PLLDrive
    h_s : float
    noise_on : dict or None
        Switches ``brownian`` and ``electronic`` (default: both on).
    scale : ndarray or None
        Core state scaling (default: the diagram's).
    layout : Layout
        The step model's parameters.

    Returns
    -------
    tuple
        ``(plan, B, sigmas)``: the plan with the shared parameters in ``base`` (the engine adds its core
        transition), the scaled core's input matrix (``v_ac`` last) and the noises' per-step deviations.
    """
    noise_on = {"brownian": True, "electronic": True, **(noise_on or {})}
    dg = pll.dg
    ss = pll_steady_state(pll)
    kx = dg.resonator.duffing_stiffness(ss.amplitude_m)
    core = pll.core_system(0.0, kx)
    S = dg.core_state_scale() if scale is None else np.asarray(scale, dtype=float)
    Sinv = 1.0 / S
    A0 = Sinv[:, None] * np.asarray(core.A) * S[None, :]
    B = Sinv[:, None] * np.asarray(core.B)
    C = np.asarray(core.C) * S[None, :]
    Aw = Sinv[:, None] * _resonator_direction(dg, core, kx, 1.0, 0.0) * S[None, :]
    Aq = Sinv[:, None] * _resonator_direction(dg, core, kx, 0.0, 1.0) * S[None, :]
    idx = {name: k for k, name in enumerate(CORE_OUTPUTS)}
    off = dg.core_output_offset()

    def lpf(block):
        sys = block.linear_model()
        Ph, Ga = zoh(np.asarray(sys.A), np.asarray(sys.B), h_s)
        return Ph, Ga[:, 0]

    Phi_pd, Gam_pd = lpf(pll.pd_lpf)
    Phi_out, Gam_out = lpf(dg.output_lpf)
    lf = pll.loop_filter
    loop = dg.amplitude_loop
    base = dict(
        w0=ss.omega_rad_s, C_vx=C[idx["v_x"]], C_vs=C[idx["v_s"]], off_vx=off[idx["v_x"]], off_vs=off[idx["v_s"]],
        f_free=pll.nco.f_free_Hz, k_vco=pll.nco.k_vco_Hz_per_V, pd_cos=np.cos(pll.detector.trim_rad),
        pd_sin=np.sin(pll.detector.trim_rad), k_amp=pll.detector.k_amp,
        Phi_pd=Phi_pd, Gam_pd=Gam_pd, kp_pll=lf.kp, ki_pll=lf.ki_per_s, v_min=lf.u_min_V, v_max=lf.u_max_V,
        **loop.smoothing_step(h_s), **loop.controller_params(), **loop.modulator_params(),
        quad_coef=dg.comb_drive.quadratic_coef_N_per_V2, vdc2=dg.comb_drive.vdc_V ** 2,
        cos_ref=1.0, sin_ref=0.0, k_demod=dg.demodulator.k_per_V, Phi_out=Phi_out, Gam_out=Gam_out, h=h_s,
    )
    plan = OperatingPlan(base=base, phi_rate=expm_derivative(A0, Aw, h_s), phi_quad=expm_derivative(A0, Aq, h_s),
                         k_quad_N_per_m=dg.resonator.k_quad_N_per_m, trim_rad=pll.rate_trim_rad, scale=S,
                         steady=ss, C_x=C[idx["x"]], C_y=C[idx["y"]], A_core=A0, layout=layout)
    plan.b_vac = B[:, -1]  # the scaled core's v_ac column (the locked initial state's forced response)
    return plan, B, noise_sigmas(dg, h_s, noise_on)


def make_pll_plan(pll: PLLDrive, h_s: float, noise_on: dict | None = None,
                  scale: np.ndarray | None = None) -> OperatingPlan:
    """Discretise the PLL-driven diagram for step ``h_s``.

    Parameters
    ----------
    pll : PLLDrive
    h_s : float
    noise_on : dict, optional
        Switches ``brownian`` and ``electronic`` (default: both on).
    scale : ndarray, optional
        Core state scaling, fixed across the operating points of a run.

    Returns
    -------
    OperatingPlan
        With ``steady`` the :class:`fmvmg_sim.pll_drive.PLLSteadyState` and ``layout`` :data:`PARAMS`.
    """
    plan, B, sig = pll_plan_common(pll, h_s, noise_on, scale, PARAMS)
    A0, ss = plan.A_core, plan.steady
    Phi, Gam = zoh(A0, B[:, :len(CORE_INPUTS)], h_s)
    G, G_w = oscillator_input(A0, B[:, -1], ss.omega_rad_s, h_s)
    plan.base.update(Phi=Phi, G=G, G_w=G_w, Gam_fx=Gam[:, CORE_INPUTS.index("F_x_ext")], Gam_w=Gam * sig[None, :])
    return plan


def pll_initial_state(plan: OperatingPlan, drive_displacement_m: float = 10e-9, from_steady: bool = False,
                      ) -> np.ndarray:
    """Initial state: at rest with a small drive displacement, the oscillator free-running; or locked.

    Parameters
    ----------
    plan : OperatingPlan
        From :func:`make_pll_plan`.
    drive_displacement_m : float, optional
        Initial drive displacement (start-up).
    from_steady : bool, optional
        Start locked, on the steady state at the plan's operating point.

    Returns
    -------
    ndarray
    """
    b, ss = plan.base, plan.steady
    z = np.zeros(plan.A_core.shape[0])
    x = dict(theta=0.0, s_pd=[0.0, 0.0], integ_pll=0.0, v_tune=0.0, s_amp=[0.0, 0.0], integ=0.0, u=0.0, n=1.0,
             s_i=[0.0, 0.0], s_q=[0.0, 0.0], t=0.0, acc_rate=0.0, acc_quad=0.0, acc_amp=0.0, acc_u=0.0,
             acc_f=0.0, acc_tune=0.0)
    if from_steady:
        # the core's forced response to K_mod u Vdac cos(w t): its states' phasors times the drive
        n = len(z)
        H = np.linalg.solve(1j * ss.omega_rad_s * np.eye(n) - plan.A_core, plan.b_vac)
        z = np.real(H * b["k_mod"] * ss.agc_effort_V * b["vdac"])
        x.update(s_amp=[b["vref"], 0.0], u=ss.agc_effort_V, v_tune=ss.v_tune_V,
                 integ=ss.agc_effort_V / b["ki"] if b["ki"] > 0 else 0.0,
                 integ_pll=ss.v_tune_V / b["ki_pll"] if b["ki_pll"] > 0 else 0.0,
                 s_i=[ss.rate_V, 0.0], s_q=[ss.quadrature_V, 0.0])
    else:
        z[0] = drive_displacement_m / plan.scale[0]
    x["z"] = z
    x["vx"] = float(b["C_vx"] @ z + b["off_vx"])
    x["vs"] = float(b["C_vs"] @ z + b["off_vs"])
    x["fq"] = b["quad_coef"] * (b["vdc2"] + (b["k_mod"] * x["u"] * b["vdac"]) ** 2)
    return STATE.pack(x)


__all__ = ["make_pll_plan", "pll_initial_state", "oscillator_input"]
