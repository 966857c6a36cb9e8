"""One step of the averaged model (see :mod:`fmvmg_sim.envelope.model`), for the compiled roll-out.

The model is linear in each of its pieces: the PI free or clamped at a limit, the carrier above
or below the normaliser's floor. A step advances with the exact discretisation of the piece it
starts in and checks the piece it ends in; a step that changed piece (the clamp reached or left,
the integrator's anti-windup switched, the drive amplitude below the floor) is flagged and the
roll-out redoes it in :data:`~fmvmg_sim.envelope.model.N_SUB` sub-steps (:func:`substep`), each
with the exact discretisation of the piece it starts in; below the floor, the carrier's
amplitude-proportional gain is applied with the trapezoid rule over a sub-step.

Scheduled inputs (rate, set-point factor, relative quadrature stiffness) come as the start and end
values of their first-order hold over the step (:meth:`fmvmg_sim.profiles.PiecewiseProfile.step_lines`),
so a step in a profile on a step edge enters at its time.

The step is written once for any state size (:class:`EnvelopeStep`): the averaged model with a closed
sense loop (:mod:`fmvmg_sim.envelope.rebalance`) has more states and reads its outputs from them.
"""

from __future__ import annotations

from blocks.ops import numpy_ops

from ..amplitude_loop import AmplitudeLoopStep
from ..numerics.layout import Layout, dot, matvec
from ..compiled import Refinement, StepModel
from .model import IA, II, IJ, IJI, IJR, IK, IS1, IYI, IYR, N, N_NOISE, N_SUB, PARAMS, piece_field

#: Integrate-and-dump accumulators, zeroed after each output sample.
RESET = ("acc_t", "acc_u")
_J = (IJ, IJR, IJI, IK)
TWO_PI = 6.283185307179586


def _at(pair, f):
    """A scheduled input's value at the fraction ``f`` of the step (linear between its start and end)."""
    if isinstance(f, (int, float)) and f == 0:
        return pair[0]
    if isinstance(f, (int, float)) and f == 1:
        return pair[1]
    return pair[0] + (pair[1] - pair[0]) * f


def _plus(x, g, s):
    return [x[i] + g[i] * s for i in range(len(x))]


class EnvelopeStep:
    """The averaged model's step and sub-step for a model of ``n`` states (the first :data:`N` the drive
    loop's and the open sense chain's, in the order of :mod:`fmvmg_sim.envelope.model`).

    Parameters
    ----------
    n : int
        States of the linear model.
    params : Layout
        Its parameter layout (:data:`fmvmg_sim.envelope.model.PARAMS` for the open sense chain).
    integrals : tuple of int
        States that integrate over an output sample (restarted at its first step).
    """

    def __init__(self, n: int, params: Layout, integrals: tuple = _J):
        self.n = n
        self.params = params
        self.integrals = integrals
        self.state = Layout([
            ("x", (n,)), ("u", ()), ("acc_t", ()), ("acc_u", ()),
            ("rate_V", ()), ("quad_V", ()), ("amp_V", ()), ("agc_V", ()), ("freq_Hz", ()), ("refine", ()),
        ])
        #: Per-step inputs: one standard normal per state but K; the rate (rad/s), set-point factor and
        #: relative quadrature-stiffness change at the start and at the end of the step; the demodulation
        #: reference phase (rad) at its end.
        self.inputs = Layout([("noise", (n - 1,)), ("rate", (2,)), ("vref_f", (2,)), ("quad_rel", (2,)), ("phase", ())])

    def _loop(self, p):
        """The amplitude loop's step face on this step's parameters."""
        return AmplitudeLoopStep(self.params, p)

    def _pi_state(self, p, x, v):
        """Unclamped PI output, its clamp state (high, low, integrator held) at state ``x`` and set-point ``v``."""
        return self._loop(p).clamp_state(x[IS1], x[II], v)

    def _hold_inputs(self, p, w, x, f0, f1):
        """The set-point and the first-order-hold input vectors at fractions ``f0`` and ``f1`` of the step."""
        S, P = self.inputs.unpack, self.params.unpack
        rate, fac, quad = S(w, "rate"), S(w, "vref_f"), S(w, "quad_rel")
        vref0, kq = P(p, "vref"), P(p, "k_quad")
        yA = P(p, "y_A")
        A = x[IA]
        Yr, Yi = x[IYR] + yA[0] * A, x[IYI] + yA[1] * A  # the sense mode as the pickoff sees it (slow part + feedthrough)
        out = []
        for f in (f0, f1):
            W, dkq = _at(rate, f), _at(quad, f) * kq
            out.append([vref0 * _at(fac, f), W * A, W * Yr, W * Yi, dkq * A, dkq * Yr, dkq * Yi])
        return out

    def _piece(self, p, piece, level, x, in0, in1):
        """The state after the step (or sub-step) in one piece, without the held input and the noise."""
        P = self.params.unpack
        a = matvec(P(p, piece_field("Phi", piece, level)), x)
        b0 = matvec(P(p, piece_field("G0", piece, level)), in0)
        b1 = matvec(P(p, piece_field("G1", piece, level)), in1)
        Gc = P(p, piece_field("Gc", piece, level))
        return [a[i] + b0[i] + b1[i] + Gc[i] for i in range(self.n)]

    def _u_integral(self, p, x, x1, v0, v1, clamped, U, dt, ops):
        """The PI output's integral over a step from ``x`` to ``x1``: the held limit, or Kp (Vref - r) + Ki I
        integrated exactly through the integrals J (of r) and K (of I)."""
        return self._loop(p).effort_integral(v0, v1, dt, x1[IJ] - x[IJ], x1[IK] - x[IK], clamped, U, ops)

    def channels(self, p, x1, inv_t, rate_V, quad_V, ops):
        """The rate and quadrature outputs of a sample from the open chain's (a closed sense loop reads its own).

        Parameters
        ----------
        p, x1 : sequence
            Parameters and the state at the sample's end.
        inv_t : float or symbolic
            One over the sample's length.
        rate_V, quad_V : float or symbolic
            The open sense chain's demodulated outputs.
        ops : object

        Returns
        -------
        tuple
            ``(rate_V, quad_V)``.
        """
        return rate_V, quad_V

    def _outputs(self, xs, p, w, x1, u_int, u1, rho1, dt, ops):
        """Integrate-and-dump outputs after a step (or sub-step) of length ``dt`` ending in ``x1``, ``u1``, the PI
        output's integral over it ``u_int``."""
        S, P = self.state.unpack, self.params.unpack
        acc_t = S(xs, "acc_t") + dt
        acc_u = S(xs, "acc_u") + u_int
        inv_t = 1.0 / acc_t
        phi1 = self.inputs.unpack(w, "phase")
        c, sn = ops.cos(phi1), ops.sin(phi1)
        RI, RQ = P(p, "R_I"), P(p, "R_Q")
        ri = [RI[0] * c - RI[1] * sn, RI[0] * sn + RI[1] * c]
        rq = [RQ[0] * c - RQ[1] * sn, RQ[0] * sn + RQ[1] * c]
        # demodulation with the (phase-rotated) references commutes with the LPF
        Jv = [x1[IJR] * inv_t, x1[IJI] * inv_t]
        g = P(p, "g_out")
        rate_V, quad_V = self.channels(p, x1, inv_t, g * dot(Jv, ri), g * dot(Jv, rq), ops)
        A1 = ops.fmax(x1[IA], 1e-15)
        bY, yA = P(p, "b_Y"), P(p, "y_A")
        Yr, Yi = x1[IYR] + yA[0] * x1[IA], x1[IYI] + yA[1] * x1[IA]
        freq = (P(p, "omega") + (P(p, "b_u") * rho1 * u1 + P(p, "b_A") * x1[IA] + bY[0] * Yr + bY[1] * Yi) / A1) / TWO_PI
        return [u1, acc_t, acc_u, rate_V, quad_V, x1[IJ] * inv_t, acc_u * inv_t, freq]

    def _restart(self, xs, ops):
        """The model state with the integrals J restarted at the first step of an output sample."""
        x = self.state.unpack(xs, "x")
        first = self.state.unpack(xs, "acc_t") <= 0
        return [ops.if_else(first, 0.0, x[i]) if i in self.integrals else x[i] for i in range(self.n)]

    def _clamp(self, u, p, ops):
        return self._loop(p).clamp(u, ops)

    def step(self, xs, p, w, ops=numpy_ops):
        """Advance the averaged model by one step in the piece it starts in; flag a change of piece.

        Parameters
        ----------
        xs : sequence
            State laid out as :attr:`state`.
        p : sequence
            Parameters laid out as :attr:`params`.
        w : sequence
            Inputs laid out as :attr:`inputs`.
        ops : object, optional
            Math backend.

        Returns
        -------
        list
            Next state; its ``refine`` field is 1 where the step must be redone in sub-steps.
        """
        P = self.params.unpack
        x = self._restart(xs, ops)
        fac = self.inputs.unpack(w, "vref_f")
        v0, v1 = P(p, "vref") * fac[0], P(p, "vref") * fac[1]
        _, high0, low0, hold0 = self._pi_state(p, x, v0)
        sat0 = high0 + low0
        U = self._loop(p).limit(high0, ops)
        in0, in1 = self._hold_inputs(p, w, x, 0, 1)
        ln = matvec(P(p, "L"), self.inputs.unpack(w, "noise"))
        free = self._piece(p, "free", "step", x, in0, in1)
        held = _plus(self._piece(p, "held", "step", x, in0, in1), P(p, piece_field("Gu", "held", "step")), U)
        held[II] = ops.if_else(hold0 > 0, x[II], held[II])
        x1 = [ops.if_else(sat0 > 0, held[i], free[i]) + ln[i] for i in range(self.n)]
        u_free1, high1, low1, hold1 = self._pi_state(p, x1, v1)
        u1 = self._clamp(u_free1, p, ops)
        af = P(p, "a_floor")
        changed = (ops.fabs(high1 - high0) + ops.fabs(low1 - low0) + sat0 * ops.fabs(hold1 - hold0)
                   + (x[IA] < af) + (x1[IA] < af))
        refine = ops.if_else(changed > 0, 1.0, 0.0)
        u_int = self._u_integral(p, x, x1, v0, v1, sat0, U, P(p, "h"), ops)
        return x1 + self._outputs(xs, p, w, x1, u_int, u1, 1.0, P(p, "h"), ops) + [refine]

    def substep(self, xs, p, wj, ops=numpy_ops):
        """Advance the averaged model by sub-step ``j`` of a refined step (the state is the previous sub-step's).

        Parameters
        ----------
        xs : sequence
            State laid out as :attr:`state`.
        p : sequence
            Parameters.
        wj : sequence
            The step's inputs (:attr:`inputs`) with the sub-step index ``j`` appended.
        ops : object, optional
            Math backend.

        Returns
        -------
        list
            State after the sub-step.
        """
        P = self.params.unpack
        n_in = self.inputs.size
        w, j = list(wj[:n_in]), wj[n_in]
        x = self._restart(xs, ops)
        f0, f1 = j * (1.0 / N_SUB), (j + 1.0) * (1.0 / N_SUB)
        fac = self.inputs.unpack(w, "vref_f")
        vref0 = P(p, "vref")
        v0, v1 = vref0 * _at(fac, f0), vref0 * _at(fac, f1)
        u_free0, high0, low0, hold0 = self._pi_state(p, x, v0)
        sat0 = high0 + low0
        U = self._loop(p).limit(high0, ops)
        in0, in1 = self._hold_inputs(p, w, x, f0, f1)
        af = P(p, "a_floor")

        def rho(A):  # the carrier's gain relative to full amplitude (the normaliser's floor)
            return ops.fmin(1.0, ops.fmax(A, 0.0) / af)

        rho0 = rho(x[IA])
        # free: the floor's deficit (rho - 1) u as a held input, trapezoidal over the sub-step
        g_f = P(p, piece_field("Gu", "free", "sub"))
        base = self._piece(p, "free", "sub", x, in0, in1)
        d0 = (rho0 - 1.0) * u_free0
        pred = _plus(base, g_f, d0)
        d1 = (rho(pred[IA]) - 1.0) * self._pi_state(p, pred, v1)[0]
        free = _plus(base, g_f, 0.5 * (d0 + d1))
        # clamped: the held limit times the carrier's gain, trapezoidal likewise
        g_h = P(p, piece_field("Gu", "held", "sub"))
        base = self._piece(p, "held", "sub", x, in0, in1)
        pred = _plus(base, g_h, U * rho0)
        held = _plus(base, g_h, U * 0.5 * (rho0 + rho(pred[IA])))
        held[II] = ops.if_else(hold0 > 0, x[II], held[II])
        last = ops.if_else(j > N_SUB - 1.5, 1.0, 0.0)  # the step's noise enters once, with the last sub-step
        ln = matvec(P(p, "L"), self.inputs.unpack(w, "noise"))
        x1 = [ops.if_else(sat0 > 0, held[i], free[i]) + last * ln[i] for i in range(self.n)]
        u1 = self._clamp(self._pi_state(p, x1, v1)[0], p, ops)
        dt = P(p, "h") * (1.0 / N_SUB)
        u_int = self._u_integral(p, x, x1, v0, v1, sat0, U, dt, ops)
        return x1 + self._outputs(xs, p, w, x1, u_int, u1, rho(x1[IA]), dt, ops) + [0.0]

    def model(self, name: str) -> StepModel:
        """The step as a compilable model, refined in :data:`~fmvmg_sim.envelope.model.N_SUB` sub-steps.

        Parameters
        ----------
        name : str
            C identifier prefix.

        Returns
        -------
        StepModel
        """
        return StepModel(name, self.state, self.params, self.inputs.size, self.step, reset=RESET,
                         refine=Refinement(self.substep, N_SUB, "refine"))


#: The averaged model of the open sense chain.
OPEN_STEP = EnvelopeStep(N, PARAMS)
STATE = OPEN_STEP.state
INPUTS = OPEN_STEP.inputs
N_IN = INPUTS.size
assert INPUTS.shapes["noise"] == (N_NOISE,)
step = OPEN_STEP.step
substep = OPEN_STEP.substep
ENVELOPE_MODEL = OPEN_STEP.model("fmvmg_envelope")
