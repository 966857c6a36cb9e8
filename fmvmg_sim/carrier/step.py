"""The whole diagram as one step function, built from the blocks' faces.

The linear core (resonator, pickoffs, amplifiers, phase shifter, modulator gain,
comb drive) is advanced by its exact discretisation, scheduled in the slowly varying
modulator gain ``g``: ``z+ = (Phi + (g - g0) Phi_g) z + Gamma w`` (first order in
``g - g0``; :func:`fmvmg_sim.numerics.discretize.expm_derivative`). The nonlinear
blocks use their carrier faces: the demodulators take the step mean of the product,
the comb drive's quadratic force is held over the next step. The amplitude loop (the
rectifier integrating ``|v|`` exactly over the step, the low-pass, the PI clamping with
anti-windup, the carrier normaliser) is its closure's step face
(:class:`fmvmg_sim.amplitude_loop.AmplitudeLoopStep`).

The same function serves numerically (numpy backend, for tests) and symbolically
(CasADi backend, for the compiled engine).
"""

from __future__ import annotations

from blocks import Multiplier
from blocks.ops import numpy_ops

from ..amplitude_loop import CARRIER_FIELDS, AmplitudeLoopStep
from ..numerics.layout import Layout, dot, lpf_step as _lpf_step, matvec

N_CORE = 8
N_NOISE = 4  # F_x Brownian, F_y Brownian, drive-front-end voltage, sense-front-end voltage

STATE = Layout([
    ("z", (N_CORE,)), ("s_amp", (2,)), ("integ", ()), ("u", ()), ("n", ()),
    ("vx", ()), ("vps", ()), ("vs", ()), ("s_i", (2,)), ("s_q", (2,)), ("fq", ()),
    ("t", ()), ("ncross", ()), ("tlast", ()),
    ("acc_rate", ()), ("acc_quad", ()), ("acc_amp", ()), ("acc_u", ()),
])

#: The sense output's fields in a step's parameters (every carrier-family step): the demodulation reference's phase
#: as cos and sin, the demodulator's gain and the output low-pass discretised for the step.
OUTPUT_FIELDS = [("cos_ref", ()), ("sin_ref", ()), ("k_demod", ()), ("Phi_out", (2, 2)), ("Gam_out", (2,))]

PARAMS = Layout([
    ("Phi", (N_CORE, N_CORE)), ("Phi_g", (N_CORE, N_CORE)), ("g0", ()),
    ("Gam_fx", (N_CORE,)), ("Gam_w", (N_CORE, N_NOISE)),
    ("C_vx", (N_CORE,)), ("C_vps", (N_CORE,)), ("C_vs", (N_CORE,)), ("off_vx", ()), ("off_vps", ()), ("off_vs", ()),
] + CARRIER_FIELDS + [  # the amplitude loop's (fmvmg_sim.amplitude_loop)
    ("quad_coef", ()), ("vdc2", ()),
] + OUTPUT_FIELDS + [("h", ())])


def step(x, p, w, ops=numpy_ops, dz=None):
    """Advance the diagram by one step.

    Parameters
    ----------
    x : sequence
        State vector laid out as :data:`STATE`.
    p : sequence
        Parameters laid out as :data:`PARAMS`.
    w : sequence
        Standard-normal noise draws for this step (length :data:`N_NOISE`).
    ops : object, optional
        Math backend (numpy or CasADi).
    dz : sequence, optional
        A further change of the core state over the step (:data:`N_CORE` values): a closed sense loop's
        feedback force and quadrature tuning (:mod:`fmvmg_sim.carrier.rebalance`).

    Returns
    -------
    list
        The next state.
    """
    S, P = STATE.unpack, PARAMS.unpack
    z = S(x, "z")
    h = P(p, "h")
    n, u = S(x, "n"), S(x, "u")
    vx0, vps0, vs0 = S(x, "vx"), S(x, "vps"), S(x, "vs")
    # --- linear core, scheduled in the modulator gain g = K_mod u n ------------------
    loop = AmplitudeLoopStep(PARAMS, p)
    g = loop.modulator_gain(u, n)
    Phi, Phi_g = P(p, "Phi"), P(p, "Phi_g")
    Gw, Gfx = P(p, "Gam_w"), P(p, "Gam_fx")
    dz_g = matvec(Phi_g, z)
    lin = matvec(Phi, z)
    wn = matvec(Gw, list(w))
    fq = S(x, "fq")
    dg = g - P(p, "g0")
    z1 = [lin[i] + dg * dz_g[i] + wn[i] + Gfx[i] * fq for i in range(N_CORE)]
    if dz is not None:
        z1 = [z1[i] + dz[i] for i in range(N_CORE)]
    vx1 = dot(P(p, "C_vx"), z1) + P(p, "off_vx")
    vps1 = dot(P(p, "C_vps"), z1) + P(p, "off_vps")
    vs1 = dot(P(p, "C_vs"), z1) + P(p, "off_vs")
    # --- amplitude loop: rectifier (3), low-pass (4), comparator (5), PI (7) -----------
    s_amp, integ1, u1 = loop.advance(S(x, "s_amp"), S(x, "integ"), vps0, vps1, h, ops)
    # --- carrier normalisation (fixed-amplitude 'Vdac sin') or the pickoff as is -------
    n1 = loop.normaliser(vx1, vps1, ops)
    # --- demodulation (13) and output low-pass (14), in phase and in quadrature --------
    c, s = P(p, "cos_ref"), P(p, "sin_ref")
    demod = Multiplier(k_per_V=P(p, "k_demod"))
    ri0, ri1 = n * (c * vps0 - s * vx0), n1 * (c * vps1 - s * vx1)
    rq0, rq1 = n * (c * vx0 + s * vps0), n1 * (c * vx1 + s * vps1)
    s_i = _lpf_step(P(p, "Phi_out"), P(p, "Gam_out"), S(x, "s_i"), demod.carrier_mean(vs0, vs1, ri0, ri1))
    s_q = _lpf_step(P(p, "Phi_out"), P(p, "Gam_out"), S(x, "s_q"), demod.carrier_mean(vs0, vs1, rq0, rq1))
    # --- quadratic comb force held over the next step -----------------------------------
    vac1 = loop.modulator_gain(u1, n1) * vps1
    fq1 = P(p, "quad_coef") * (P(p, "vdc2") + vac1 * vac1)
    # --- frequency counter: rising zero crossings of v_x, interpolated -----------------
    t0 = S(x, "t")
    up = (vx0 < 0) * (vx1 >= 0)
    tc = t0 + h * (-vx0) / ops.if_else(up, vx1 - vx0, 1.0)
    ncross = S(x, "ncross") + up
    tlast = ops.if_else(up, tc, S(x, "tlast"))
    # integrate-and-dump outputs (sums over the output interval; the roll-out zeroes them after each sample)
    acc = [S(x, "acc_rate") + s_i[0], S(x, "acc_quad") + s_q[0], S(x, "acc_amp") + s_amp[0], S(x, "acc_u") + u1]
    return z1 + s_amp + [integ1, u1, n1, vx1, vps1, vs1] + s_i + s_q + [fq1, t0 + h, ncross, tlast] + acc


from ..compiled import StepModel  # noqa: E402

#: The carrier step as a compilable model.
CARRIER_MODEL = StepModel("fmvmg_carrier", STATE, PARAMS, N_NOISE, step,
                          reset=("acc_rate", "acc_quad", "acc_amp", "acc_u"))

__all__ = ["STATE", "PARAMS", "OUTPUT_FIELDS", "N_CORE", "N_NOISE", "step", "CARRIER_MODEL"]
