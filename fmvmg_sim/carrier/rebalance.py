"""The carrier step with a closed sense loop: force-to-rebalance and quadrature control (:mod:`fmvmg_sim.rebalance`).

The diagram's step (:func:`fmvmg_sim.carrier.step.step`) advances as without the loops, with two more
changes of the core state over each step: the feedback force on the sense mode, held over the step,
and the quadrature-tuning stiffness, to first order through the exact directional derivative of the
core's transition matrix (as the modulator gain enters). Each step then

* demodulates the sense output in phase and in quadrature (the step mean of the product, as the
  output demodulators do) and advances each loop's controller by its exact discretisation;
* sets the force for the next step: ``p_I K_fb k_m u_I`` times the carrier at the middle of that step
  (the carrier advanced by half a step from the two drive signals, exact for a sinusoid), divided by
  the zero-order hold's gain ``sinc(w h / 2)``, so the held force has the continuous force's fundamental;
* sets the tuning stiffness ``p_Q k_t V_t`` for the next step;
* feeds the output low-pass (14) with ``u_I`` for ``rate_V`` (force-to-rebalance) and ``V_t`` for
  ``quadrature_V`` (quadrature control), each the mean of its start and end values over the step.
"""

from __future__ import annotations

import numpy as np

from blocks import RebalanceController
from blocks.ops import numpy_ops

from ..averaged import carrier_phasors
from ..compiled import StepModel
from ..diagram import Diagram
from ..numerics.discretize import zoh
from ..numerics.layout import Layout, dot, matvec
from .plan import OperatingPlan, initial_state, make_plan
from .step import CARRIER_MODEL, N_CORE, N_NOISE, PARAMS, STATE, step

#: States of each loop's controller (:class:`blocks.RebalanceController`).
NC = len(RebalanceController.states)
STATE_R = Layout(STATE.fields + [("fy", ()), ("dkq", ()), ("ctl_i", (NC,)), ("ctl_q", (NC,)), ("u_fb", ()),
                                 ("v_t", ())])
PARAMS_R = Layout(PARAMS.fields + [
    ("Gam_fy", (N_CORE,)), ("Phi_dq", (N_CORE, N_CORE)),
    ("Phi_ci", (NC, NC)), ("Gam_ci", (NC,)), ("C_ci", (NC,)), ("Phi_cq", (NC, NC)), ("Gam_cq", (NC,)), ("C_cq", (NC,)),
    ("k_fb", ()), ("k_qt", ()), ("ftr", ()), ("qc", ()), ("mid_x", ()), ("mid_ps", ()),
])


def step_rebalance(x, p, w, ops=numpy_ops):
    """Advance the diagram with its closed sense loops by one step.

    Parameters
    ----------
    x : sequence
        State laid out as :data:`STATE_R`.
    p : sequence
        Parameters laid out as :data:`PARAMS_R`.
    w : sequence
        Standard-normal noise draws (length :data:`~fmvmg_sim.carrier.step.N_NOISE`).
    ops : object, optional
        Math backend.

    Returns
    -------
    list
        The next state.
    """
    S, P = STATE_R.unpack, PARAMS_R.unpack
    nb = STATE.size
    z = S(x, "z")
    dzq = matvec(P(p, "Phi_dq"), z)
    fy, dkq = S(x, "fy"), S(x, "dkq")
    gfy = P(p, "Gam_fy")
    dz = [gfy[i] * fy + dkq * dzq[i] for i in range(N_CORE)]
    y = step(list(x[:nb]), p, w, ops, dz=dz)
    B = lambda v, name: STATE.unpack(v, name)  # noqa: E731
    n0, vx0, vps0, vs0 = B(x, "n"), B(x, "vx"), B(x, "vps"), B(x, "vs")
    n1, vx1, vps1, vs1 = B(y, "n"), B(y, "vx"), B(y, "vps"), B(y, "vs")
    c, s = P(p, "cos_ref"), P(p, "sin_ref")
    kd = 0.5 * P(p, "k_demod")
    e_i = kd * (vs0 * n0 * (c * vps0 - s * vx0) + vs1 * n1 * (c * vps1 - s * vx1))
    e_q = kd * (vs0 * n0 * (c * vx0 + s * vps0) + vs1 * n1 * (c * vx1 + s * vps1))
    ci = _ctl(P(p, "Phi_ci"), P(p, "Gam_ci"), S(x, "ctl_i"), e_i)
    cq = _ctl(P(p, "Phi_cq"), P(p, "Gam_cq"), S(x, "ctl_q"), e_q)
    u1, v1 = dot(P(p, "C_ci"), ci), dot(P(p, "C_cq"), cq)
    ftr, qc = P(p, "ftr"), P(p, "qc")
    fy1 = ftr * P(p, "k_fb") * u1 * n1 * (P(p, "mid_x") * vx1 + P(p, "mid_ps") * vps1)
    dkq1 = qc * P(p, "k_qt") * v1
    # the output low-pass reads the loops' efforts instead of the demodulators
    Po, Go = P(p, "Phi_out"), P(p, "Gam_out")
    si = _lpf(Po, Go, S(x, "s_i"), 0.5 * (S(x, "u_fb") + u1))
    sq = _lpf(Po, Go, S(x, "s_q"), 0.5 * (S(x, "v_t") + v1))
    si = [ftr * si[k] + (1 - ftr) * B(y, "s_i")[k] for k in range(2)]
    sq = [qc * sq[k] + (1 - qc) * B(y, "s_q")[k] for k in range(2)]
    acc_rate = ftr * (S(x, "acc_rate") + si[0]) + (1 - ftr) * B(y, "acc_rate")
    acc_quad = qc * (S(x, "acc_quad") + sq[0]) + (1 - qc) * B(y, "acc_quad")
    y = list(y)
    for name, val in (("s_i", si), ("s_q", sq), ("acc_rate", acc_rate), ("acc_quad", acc_quad)):
        sl = STATE.slices[name]
        y[sl] = val if isinstance(val, list) else [val]
    return y + [fy1, dkq1] + ci + cq + [u1, v1]


def _ctl(Phi, Gam, c, e):
    out = matvec(Phi, c)
    return [out[k] + Gam[k] * e for k in range(NC)]


def _lpf(Phi, Gam, s, u):
    return [Phi[0][0] * s[0] + Phi[0][1] * s[1] + Gam[0] * u, Phi[1][0] * s[0] + Phi[1][1] * s[1] + Gam[1] * u]


#: The carrier step with closed sense loops as a compilable model.
CARRIER_REBALANCE_MODEL = StepModel("fmvmg_carrier_rebalance", STATE_R, PARAMS_R, N_NOISE, step_rebalance,
                                    reset=CARRIER_MODEL.reset)


def model_for(dg: Diagram) -> StepModel:
    """The carrier model a diagram runs in: with the closed-loop sense's states when it has one.

    Parameters
    ----------
    dg : Diagram

    Returns
    -------
    StepModel
    """
    return CARRIER_MODEL if dg.sense_loop is None else CARRIER_REBALANCE_MODEL


def loop_plan(dg: Diagram, h_s: float, noise_on: dict | None = None, scale: np.ndarray | None = None) -> OperatingPlan:
    """:func:`~fmvmg_sim.carrier.plan.make_plan` with the closed sense loops' numbers when the diagram has them.

    Parameters
    ----------
    dg : Diagram
    h_s : float
    noise_on : dict, optional
    scale : ndarray, optional

    Returns
    -------
    OperatingPlan
    """
    plan = make_plan(dg, h_s, noise_on, scale)
    loop = dg.sense_loop
    if loop is None:
        return plan
    ss = plan.steady
    w, A = ss.omega_rad_s, ss.amplitude_m
    Hx, Hps = dg.drive_chain_response(w), dg.phase_shifter_response(w)
    carrier, R_I, R_Q = carrier_phasors(dg, Hx * A, Hx * Hps * A)
    p_i, p_q = loop.polarities(dg, w, A, carrier, R_I, R_Q)
    # the carrier half a step on from the two drive signals (v_ps = H_ps v_x, exact for a sinusoid)
    phi, psi = 0.5 * w * h_s, float(np.angle(Hps))
    mid_x, mid_ps = -np.sin(phi) / np.sin(psi), np.sin(psi + phi) / np.sin(psi)
    b = plan.base
    for key, blk in (("ci", loop.controller), ("cq", loop.quad_controller)):
        A_c, B_c, C_c, _ = blk.state_space_matrices()
        Phi_c, Gam_c = zoh(A_c, B_c, h_s)
        b[f"Phi_{key}"], b[f"Gam_{key}"], b[f"C_{key}"] = Phi_c, Gam_c[:, 0], C_c[0]
    b.update(Phi_dq=plan.phi_quad, k_fb=p_i * loop.comb.linear_coef_N_per_V * loop.remodulator.k_per_V / np.sinc(phi / np.pi),
             k_qt=p_q * loop.electrodes.dk_dV_N_per_m_per_V, ftr=float(loop.force_rebalance),
             qc=float(loop.quadrature_control), mid_x=mid_x, mid_ps=mid_ps)
    plan.layout = PARAMS_R
    plan._packed = None
    return plan


def loop_initial_state(plan: OperatingPlan, drive_displacement_m: float = 10e-9, from_steady: bool = False) -> np.ndarray:
    """:func:`~fmvmg_sim.carrier.plan.initial_state`, extended by the closed sense loops' states.

    Parameters
    ----------
    plan : OperatingPlan
    drive_displacement_m : float, optional
    from_steady : bool, optional
        Start on the averaged steady state: the loops' integrators hold their steady efforts.

    Returns
    -------
    ndarray
    """
    x = initial_state(plan, drive_displacement_m, from_steady)
    if plan.layout is PARAMS:
        return x
    b = plan.base
    u = v = 0.0
    if from_steady:
        k_out = _dc_gain(b["Phi_out"], b["Gam_out"])
        u = plan.steady.rate_V / k_out if b["ftr"] else 0.0
        v = plan.steady.quadrature_V / k_out if b["qc"] else 0.0
    if from_steady:  # the sense mode as the loops hold it (the core's first states are the resonator's x, x', y, y')
        ss = plan.steady
        x[STATE.slices["z"].start + 2] = ss.Y.real / plan.scale[2]
        x[STATE.slices["z"].start + 3] = (1j * ss.omega_rad_s * ss.Y).real / plan.scale[3]
    ci = _hold(b["C_ci"], u)
    cq = _hold(b["C_cq"], v)
    n, vx, vps = (float(x[STATE.slices[name].start]) for name in ("n", "vx", "vps"))
    fy = b["ftr"] * b["k_fb"] * u * n * (b["mid_x"] * vx + b["mid_ps"] * vps)
    return np.concatenate([x, [fy, b["qc"] * b["k_qt"] * v], ci, cq, [u, v]])


def _dc_gain(Phi, Gam) -> float:
    """DC gain of a discretised low-pass's first state."""
    return float(np.linalg.solve(np.eye(2) - np.asarray(Phi), np.asarray(Gam))[0])


def _hold(C, u: float) -> np.ndarray:
    """The controller state (low-pass at zero, integrator) whose output is ``u``."""
    ki = float(C[-1])
    out = np.zeros(NC)
    out[-1] = u / ki if ki else 0.0
    return out


__all__ = ["STATE_R", "PARAMS_R", "step_rebalance", "CARRIER_REBALANCE_MODEL", "model_for", "loop_plan",
           "loop_initial_state"]
