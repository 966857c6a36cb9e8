"""Numbers for the compiled step: the diagram at an operating point, discretised exactly."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..averaged import SteadyState, steady_state
from ..diagram import CORE_INPUTS, CORE_OUTPUTS, Diagram
from ..numerics.discretize import expm_derivative, zoh
from ..numerics.layout import Layout
from .step import N_CORE, PARAMS, STATE


@dataclass
class OperatingPlan:
    """Discretised diagram at one operating point (temperature) for step ``h_s``.

    Attributes
    ----------
    base : dict
        Parameter fields (see :data:`fmvmg_sim.carrier.step.PARAMS`) at zero rate.
    phi_rate : ndarray
        Derivative of the core transition matrix per rad/s of input rate.
    scale : ndarray
        Core state scaling (physical = scale * internal).
    steady : SteadyState
        The averaged steady state used as the linearisation point.
    """

    base: dict
    phi_rate: np.ndarray
    phi_quad: np.ndarray
    k_quad_N_per_m: float
    trim_rad: float
    scale: np.ndarray
    steady: SteadyState
    C_x: np.ndarray
    C_y: np.ndarray
    A_core: np.ndarray
    _packed: np.ndarray | None = None
    #: The parameter layout ``base`` packs into (another step model's: the PLL drive's, a closed sense loop's).
    layout: Layout = PARAMS

    def params(self, rate_rad_s=0.0, phase_offset_rad=0.0, vref_factor=1.0, quad_rel=0.0) -> np.ndarray:
        """Packed parameter vectors, one row per output sample (vectorised over the arguments).

        Parameters
        ----------
        rate_rad_s : float or ndarray, optional
            Input rate.
        phase_offset_rad : float or ndarray, optional
            Extra demodulation-reference phase (flicker), on top of the trimmed reference phase.
        vref_factor : float or ndarray, optional
            Multiplier of the amplitude set-point.
        quad_rel : float or ndarray, optional
            Relative change of the quadrature stiffness (hysteresis, relaxation effects).

        Returns
        -------
        ndarray, shape (k, n_p)
        """
        rate = np.atleast_1d(np.asarray(rate_rad_s, dtype=float))
        k = max(rate.size, np.size(phase_offset_rad), np.size(vref_factor), np.size(quad_rel))
        layout = self.layout
        if self._packed is None:
            self._packed = layout.pack(self.base)
        P = np.repeat(self._packed[None, :], k, axis=0)
        P[:, layout.slices["Phi"]] += np.broadcast_to(rate, (k,))[:, None] * self.phi_rate.ravel()[None, :]
        dq = self.k_quad_N_per_m * np.broadcast_to(np.asarray(quad_rel, dtype=float), (k,))
        if np.any(dq):
            P[:, layout.slices["Phi"]] += dq[:, None] * self.phi_quad.ravel()[None, :]
        ph = self.trim_rad + np.broadcast_to(np.asarray(phase_offset_rad, dtype=float), (k,))
        P[:, layout.slices["cos_ref"]] = np.cos(ph)[:, None]
        P[:, layout.slices["sin_ref"]] = np.sin(ph)[:, None]
        P[:, layout.slices["vref"]] = self.base["vref"] * np.broadcast_to(np.asarray(vref_factor, dtype=float), (k,))[:, None]
        return P


def make_plan(dg: Diagram, h_s: float, noise_on: dict | None = None, scale: np.ndarray | None = None) -> OperatingPlan:
    """Discretise ``dg`` for step ``h_s``.

    Parameters
    ----------
    dg : Diagram
    h_s : float
        Step length.
    noise_on : dict, optional
        Switches ``brownian`` and ``electronic`` (default: both on).
    scale : ndarray, optional
        Core state scaling; keep it fixed across operating points of one run so the
        state carries over unchanged (default: the diagram's own).

    Returns
    -------
    OperatingPlan
    """
    noise_on = {"brownian": True, "electronic": True, **(noise_on or {})}
    ss = steady_state(dg)
    g0 = ss.modulator_gain
    kx = dg.resonator.duffing_stiffness(ss.amplitude_m)  # Duffing: describing-function stiffness at the amplitude
    core0 = dg.core_system(g0, 0.0, kx)
    core_g = dg.core_system(g0 + 1.0, 0.0, kx)
    S = dg.core_state_scale() if scale is None else np.asarray(scale, dtype=float)
    Sinv = 1.0 / S
    A0 = Sinv[:, None] * np.asarray(core0.A) * S[None, :]
    Ag = Sinv[:, None] * (np.asarray(core_g.A) - np.asarray(core0.A)) * S[None, :]
    Aw = Sinv[:, None] * _resonator_direction(dg, core0, kx, 1.0, 0.0) * S[None, :]
    Aq = Sinv[:, None] * _resonator_direction(dg, core0, kx, 0.0, 1.0) * S[None, :]
    B = Sinv[:, None] * np.asarray(core0.B)
    C = np.asarray(core0.C) * S[None, :]
    D = np.asarray(core0.D)
    if np.any(D[:3] != 0):
        raise ValueError("the core's voltage outputs must not feed through inputs directly")
    Phi, Gam = zoh(A0, B, h_s)
    Phi_g = expm_derivative(A0, Ag, h_s)
    Phi_w = expm_derivative(A0, Aw, h_s)
    Phi_q = expm_derivative(A0, Aq, h_s)
    sig = noise_sigmas(dg, h_s, noise_on)
    idx = {name: k for k, name in enumerate(CORE_OUTPUTS)}
    off = dg.core_output_offset()
    ol = dg.output_lpf.linear_model()
    Phi_out, Gam_out = zoh(np.asarray(ol.A), np.asarray(ol.B), h_s)
    base = dict(
        Phi=Phi, Phi_g=Phi_g, g0=g0, Gam_fx=Gam[:, CORE_INPUTS.index("F_x_ext")], Gam_w=Gam * sig[None, :],
        C_vx=C[idx["v_x"]], C_vps=C[idx["v_ps"]], C_vs=C[idx["v_s"]],
        off_vx=off[idx["v_x"]], off_vps=off[idx["v_ps"]], off_vs=off[idx["v_s"]],
        **dg.amplitude_loop.carrier_params(ss.omega_rad_s, h_s), quad_coef=dg.comb_drive.quadratic_coef_N_per_V2,
        vdc2=dg.comb_drive.vdc_V ** 2, cos_ref=1.0, sin_ref=0.0, k_demod=dg.demodulator.k_per_V,
        Phi_out=Phi_out, Gam_out=Gam_out[:, 0], h=h_s,
        Gam_fy=Gam[:, CORE_INPUTS.index("F_y_ext")],  # a closed sense loop's force (carrier.rebalance)
    )
    return OperatingPlan(base=base, phi_rate=Phi_w, phi_quad=Phi_q, k_quad_N_per_m=dg.resonator.k_quad_N_per_m,
                         trim_rad=dg.phase_trim_rad, scale=S, steady=ss,
                         C_x=C[idx["x"]], C_y=C[idx["y"]], A_core=A0)


def noise_sigmas(dg: Diagram, h_s: float, noise_on: dict) -> np.ndarray:
    """Standard deviations per step of the core's white-noise inputs held over a step of ``h_s``.

    One-sided PSD ``S`` gives the variance ``S / (2 h)``; order: F_x and F_y Brownian forces, drive and
    sense front-end voltages (:data:`fmvmg_sim.diagram.CORE_INPUTS` after ``F_x_ext``).

    Parameters
    ----------
    dg : Diagram
    h_s : float
    noise_on : dict
        Switches ``brownian`` and ``electronic``.

    Returns
    -------
    ndarray
    """
    psd_fx, psd_fy = dg.resonator.brownian_force_psd_N2_per_Hz()
    nz = dg.noise
    return np.array([
        np.sqrt(psd_fx / (2 * h_s)) if noise_on["brownian"] else 0.0,
        np.sqrt(psd_fy / (2 * h_s)) if noise_on["brownian"] else 0.0,
        nz["drive_input_V_per_sqrtHz"] / np.sqrt(2 * h_s) if noise_on["electronic"] else 0.0,
        nz["sense_input_V_per_sqrtHz"] / np.sqrt(2 * h_s) if noise_on["electronic"] else 0.0,
    ])


def _resonator_direction(dg: Diagram, core0, kx: float, rate_rad_s: float, dk_quad_N_per_m: float) -> np.ndarray:
    """Change of the core's state matrix per unit of rate or of quadrature stiffness.

    Both act inside the resonator only (its state matrix is affine in them, and no other block
    feeds the entries they touch), so the change is the resonator's own, placed at its states in
    the core: the same numbers as differencing two interconnected cores, without building them.
    """
    res = dg.resonator
    R0 = res.state_matrix(0.0, kx)
    R1 = res.state_matrix(rate_rad_s, kx)
    if dk_quad_N_per_m:
        R1 = R1.copy()
        R1[1, 2] -= dk_quad_N_per_m / res.m_drive_kg
        R1[3, 0] -= dk_quad_N_per_m / res.m_sense_kg
    labels = list(core0.state_labels)
    names = [f"resonator_{s}" for s in res.linear_model().state_labels]
    if not set(names) <= set(labels):
        raise RuntimeError(f"the core's states {labels} do not name the resonator's {names}")
    idx = [labels.index(n) for n in names]
    out = np.zeros_like(np.asarray(core0.A, dtype=float))
    out[np.ix_(idx, idx)] = R1 - R0
    return out


def initial_state(plan: OperatingPlan, drive_displacement_m: float = 10e-9, from_steady: bool = False) -> np.ndarray:
    """Initial state: the loop at rest with a small drive displacement, or at its steady state.

    Parameters
    ----------
    plan : OperatingPlan
    drive_displacement_m : float, optional
        Initial drive displacement (start-up from a perturbation).
    from_steady : bool, optional
        Start on the averaged steady state (zero-rate) instead; the fast states are
        set from the steady drive motion and the slow ones from the steady outputs.

    Returns
    -------
    ndarray
    """
    b = plan.base
    ss = plan.steady
    if from_steady:
        # the core's oscillating eigenmode at the steady modulator gain, scaled to the steady amplitude
        lam, vec = np.linalg.eig(plan.A_core)
        k = int(np.argmin(np.abs(lam - 1j * ss.omega_rad_s)))
        mode = vec[:, k] / (plan.C_x @ vec[:, k])
        z = np.real(ss.amplitude_m * mode)
    else:
        z = np.zeros(N_CORE)
        z[0] = drive_displacement_m / plan.scale[0]
    vx = float(b["C_vx"] @ z + b["off_vx"])
    vps = float(b["C_vps"] @ z + b["off_vps"])
    vs = float(b["C_vs"] @ z + b["off_vs"])
    amp = max(np.hypot(vx, vps), b["n_floor_V"])
    n = b["vdac"] / amp if b["normalized"] else 1.0
    x = dict(z=z, s_amp=[0.0, 0.0], integ=0.0, u=0.0, n=n, vx=vx, vps=vps, vs=vs, s_i=[0.0, 0.0], s_q=[0.0, 0.0],
             fq=b["quad_coef"] * b["vdc2"], t=0.0, ncross=0.0, tlast=0.0,
             acc_rate=0.0, acc_quad=0.0, acc_amp=0.0, acc_u=0.0)
    if from_steady:
        x["s_amp"] = [b["vref"], 0.0]
        x["u"] = ss.agc_effort_V
        x["integ"] = (ss.agc_effort_V) / b["ki"] if b["ki"] > 0 else 0.0
        x["s_i"] = [ss.rate_V, 0.0]
        x["s_q"] = [ss.quadrature_V, 0.0]
    return STATE.pack(x)


__all__ = ["OperatingPlan", "make_plan", "initial_state", "noise_sigmas"]
