"""One step of the averaged model (see :mod:`fmvmg_sim.envelope.model`), for the compiled roll-out."""

from __future__ import annotations

from blocks.ops import numpy_ops

from ..carrier.layout import Layout, dot, matvec
from ..compiled import StepModel
from .model import IA, II, IJ, IJI, IJR, IS1, ISI, ISR, IYI, IYR, N, PARAMS

STATE = Layout([
    ("x", (N,)), ("u", ()), ("w_rate", ()), ("vref_f", ()), ("dkq", ()),
    ("acc_t", ()), ("acc_u", ()), ("rate_V", ()), ("quad_V", ()), ("amp_V", ()), ("agc_V", ()), ("freq_Hz", ()),
])
#: Per-step inputs: N standard normals, then rate (rad/s), set-point factor, reference phase (rad) and the
#: relative quadrature-stiffness change.
N_IN = N + 4
#: Integrate-and-dump accumulators, zeroed after each output sample.
RESET = ("acc_t", "acc_u")
_J = (IJ, IJR, IJI)
TWO_PI = 6.283185307179586


def step(xs, p, w, ops=numpy_ops):
    """Advance the averaged model by one step.

    Parameters
    ----------
    xs : sequence
        State laid out as :data:`STATE`.
    p : sequence
        Parameters laid out as :data:`fmvmg_sim.envelope.model.PARAMS`.
    w : sequence
        ``N`` standard normals, then the rate, set-point factor and reference phase at the end of the step.
    ops : object, optional
        Math backend.

    Returns
    -------
    list
        Next state.
    """
    S, P = STATE.unpack, PARAMS.unpack
    x = S(xs, "x")
    # the integrals J restart with each output sample (acc_t was zeroed with them)
    first = S(xs, "acc_t") <= 0
    x = [ops.if_else(first, 0.0, x[i]) if i in _J else x[i] for i in range(N)]
    noise = list(w[0:N])
    rate1, fac1, phi1 = w[N], w[N + 1], w[N + 2]
    dkq1 = w[N + 3] * P(p, "k_quad")
    rate0, fac0, dkq0 = S(xs, "w_rate"), S(xs, "vref_f"), S(xs, "dkq")
    h = P(p, "h")
    vref0 = P(p, "vref0")
    v0, v1 = vref0 * fac0, vref0 * fac1
    kp, ki, umin, umax = P(p, "kp"), P(p, "ki"), P(p, "u_min"), P(p, "u_max")
    u_free = kp * (v0 - x[IS1]) + ki * x[II]
    sat = (u_free > umax) + (u_free < umin)
    u_held = ops.fmin(ops.fmax(u_free, umin), umax)
    A, Yr, Yi = x[IA], x[IYR], x[IYI]
    in0 = [v0, rate0 * A, rate0 * Yr, rate0 * Yi, dkq0 * A, dkq0 * Yr, dkq0 * Yi]
    in1 = [v1, rate1 * A, rate1 * Yr, rate1 * Yi, dkq1 * A, dkq1 * Yr, dkq1 * Yi]
    ln = matvec(P(p, "L"), noise)
    a = matvec(P(p, "Phi"), x)
    b0 = matvec(P(p, "G0"), in0)
    b1 = matvec(P(p, "G1"), in1)
    Gc = P(p, "Gc")
    free = [a[i] + b0[i] + b1[i] + Gc[i] + ln[i] for i in range(N)]
    a_s = matvec(P(p, "Phi_s"), x)
    b0s = matvec(P(p, "G0_s"), in0)
    b1s = matvec(P(p, "G1_s"), in1)
    Gus, Gcs = P(p, "Gu_s"), P(p, "Gc_s")
    held = [a_s[i] + b0s[i] + b1s[i] + Gus[i] * u_held + Gcs[i] + ln[i] for i in range(N)]
    x1 = [ops.if_else(sat > 0, held[i], free[i]) for i in range(N)]
    u1 = ops.fmin(ops.fmax(kp * (v1 - x1[IS1]) + ki * x1[II], umin), umax)
    # integrate-and-dump outputs; demodulation with the (phase-rotated) references commutes with the LPF
    acc_t = S(xs, "acc_t") + h
    acc_u = S(xs, "acc_u") + 0.5 * (S(xs, "u") + u1) * h
    inv_t = 1.0 / acc_t
    c, sn = ops.cos(phi1), ops.sin(phi1)
    RI, RQ = P(p, "R_I"), P(p, "R_Q")
    ri = [RI[0] * c - RI[1] * sn, RI[0] * sn + RI[1] * c]
    rq = [RQ[0] * c - RQ[1] * sn, RQ[0] * sn + RQ[1] * c]
    Jv = [x1[IJR] * inv_t, x1[IJI] * inv_t]
    g = P(p, "g_out")
    rate_V = g * dot(Jv, ri)
    quad_V = g * dot(Jv, rq)
    A1 = ops.fmax(x1[IA], 1e-15)
    bY = P(p, "b_Y")
    freq = (P(p, "omega") + (P(p, "b_u") * u1 + P(p, "b_A") * x1[IA] + bY[0] * x1[IYR] + bY[1] * x1[IYI]) / A1) / TWO_PI
    return x1 + [u1, rate1, fac1, dkq1, acc_t, acc_u, rate_V, quad_V, x1[IJ] * inv_t, acc_u * inv_t, freq]


ENVELOPE_MODEL = StepModel("fmvmg_envelope", STATE, PARAMS, N_IN, step, reset=RESET)
