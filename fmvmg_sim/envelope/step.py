"""One step of the averaged model (see :mod:`fmvmg_sim.envelope.model`), for the compiled roll-out."""

from __future__ import annotations

from blocks.ops import numpy_ops

from ..carrier.layout import Layout, dot, matvec
from ..compiled import StepModel
from .model import ND, NS, PARAMS

STATE = Layout([
    ("d", (ND - 1,)), ("jd", ()), ("s", (NS - 2,)), ("js", (2,)), ("u", ()), ("w_rate", ()), ("vref_f", ()),
    ("acc_t", ()), ("acc_u", ()), ("rate_V", ()), ("quad_V", ()), ("amp_V", ()), ("agc_V", ()), ("freq_Hz", ()),
])
#: Per-step inputs: drive noise (ND), sense noise (NS), rate (rad/s), set-point factor, reference phase (rad).
N_IN = ND + NS + 3
#: Integrate-and-dump accumulators, zeroed after each output sample.
RESET = ("acc_t", "acc_u", "jd", "js")
TWO_PI = 6.283185307179586


def step(x, p, w, ops=numpy_ops):
    """Advance the averaged model by one step.

    Parameters
    ----------
    x : sequence
        State laid out as :data:`STATE`.
    p : sequence
        Parameters laid out as :data:`fmvmg_sim.envelope.model.PARAMS`.
    w : sequence
        Inputs: 4 + 6 standard normals, then the rate, set-point factor and reference
        phase at the end of the step.
    ops : object, optional
        Math backend.

    Returns
    -------
    list
        Next state.
    """
    S, P = STATE.unpack, PARAMS.unpack
    d = S(x, "d") + [S(x, "jd")]
    nd, ns = list(w[0:ND]), list(w[ND:ND + NS])
    rate1, fac1, phi1 = w[ND + NS], w[ND + NS + 1], w[ND + NS + 2]
    h = P(p, "h")
    vref0 = P(p, "vref0")
    v0, v1 = vref0 * S(x, "vref_f"), vref0 * fac1
    kp, ki, umin, umax = P(p, "kp"), P(p, "ki"), P(p, "u_min"), P(p, "u_max")
    u_free = kp * (v0 - d[1]) + ki * d[3]
    sat = (u_free > umax) + (u_free < umin)
    u_held = ops.fmin(ops.fmax(u_free, umin), umax)
    # unsaturated: exact closed-loop step
    lin = matvec(P(p, "Phi_d"), d)
    Ld = matvec(P(p, "L_d"), nd)
    G0, G1, Gc = P(p, "Gd0"), P(p, "Gd1"), P(p, "Gdc")
    d_free = [lin[i] + G0[i] * v0 + G1[i] * v1 + Gc[i] + Ld[i] for i in range(ND)]
    # saturated: u held, integrator held
    keep = [0, 1, 2, 4]
    lin_s = matvec(P(p, "Phi_ds"), [d[i] for i in keep])
    Gu, Gsc = P(p, "Gdsu"), P(p, "Gdsc")
    ds = [lin_s[j] + Gu[j] * u_held + Gsc[j] + Ld[keep[j]] for j in range(4)]
    d_sat = [ds[0], ds[1], ds[2], d[3], ds[3]]
    d1 = [ops.if_else(sat > 0, d_sat[i], d_free[i]) for i in range(ND)]
    u1 = ops.fmin(ops.fmax(kp * (v1 - d1[1]) + ki * d1[3], umin), umax)
    # sense: FOH inputs [A, W A, u]
    u0 = S(x, "u")
    in0 = [d[0], S(x, "w_rate") * d[0], u0]
    in1 = [d1[0], rate1 * d1[0], u1]
    sv = S(x, "s") + S(x, "js")
    a = matvec(P(p, "Phi_s"), sv)
    b0 = matvec(P(p, "Gs0"), in0)
    b1 = matvec(P(p, "Gs1"), in1)
    ln = matvec(P(p, "L_s"), ns)
    s1 = [a[i] + b0[i] + b1[i] + ln[i] for i in range(NS)]
    # integrate-and-dump outputs: the accumulators J (exact integrals) are zeroed with acc_t after each
    # output sample; demodulation with the (phase-rotated) references commutes with the LPF
    acc_t = S(x, "acc_t") + h
    acc_u = S(x, "acc_u") + 0.5 * (u0 + u1) * h
    inv_t = 1.0 / acc_t
    c, sn = ops.cos(phi1), ops.sin(phi1)
    RI, RQ = P(p, "R_I"), P(p, "R_Q")
    ri = [RI[0] * c - RI[1] * sn, RI[0] * sn + RI[1] * c]
    rq = [RQ[0] * c - RQ[1] * sn, RQ[0] * sn + RQ[1] * c]
    Jv = [s1[6] * inv_t, s1[7] * inv_t]
    g = P(p, "g_out")
    rate_V = g * dot(Jv, ri)
    quad_V = g * dot(Jv, rq)
    A1 = ops.fmax(d1[0], 1e-15)
    freq = (P(p, "omega") + (P(p, "b_u") * u1 - P(p, "b_A") * d1[0]) / A1) / TWO_PI
    return d1 + s1 + [u1, rate1, fac1, acc_t, acc_u, rate_V, quad_V, d1[4] * inv_t, acc_u * inv_t, freq]


ENVELOPE_MODEL = StepModel("fmvmg_envelope", STATE, PARAMS, N_IN, step, reset=RESET)
