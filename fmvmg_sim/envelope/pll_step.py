"""The PLL drive's envelope step: the linear core's complex envelope in the oscillator's frame.

With the oscillator at phase ``theta`` (frequency ``w = 2 pi (f_free + K_vco v_tune)``) every core
signal is ``q = Re(Z e^{j theta})``. The complex envelope obeys ``Z' = (A - j w) Z + b a + B N``:
linear, with the frequency offset as its only bilinear term (``a = K_mod u Vdac`` the drive's
amplitude, ``N`` the white noises' complex envelopes). Over a step with ``w`` held it is exact:
``Z+ = e^{-j w h} (Phi Z + a G(w)) + noise``, ``Phi = e^{A h}`` and ``G(w) = int_0^h e^{A(h-s)} b e^{j w s} ds``
scheduled to first order in ``w - w0``. The fast pole near ``-2w`` (each mode's conjugate) is kept,
exactly; the initial state carries only the positive-frequency part, so it stays small. The phase
detector, amplitude channel and rate demodulators read the envelopes' products with the
references (their DC parts: the 2-omega terms are what their low-passes remove in the carrier
engine); the quadratic comb force (DC and 2-omega) and the amplifiers' offsets do not reach the
envelope.
"""

from __future__ import annotations

import numpy as np

from blocks.ops import numpy_ops

from ..amplitude_loop import CONTROLLER_FIELDS, MODULATOR_FIELDS, SMOOTHING_FIELDS, AmplitudeLoopStep
from ..carrier.step import N_CORE, OUTPUT_FIELDS
from ..compiled import StepModel
from ..pll_drive import PHASE_LOOP_FIELDS, regulate_phase
from ..numerics.layout import Layout, dot, lpf_step as _lpf_step, matvec

#: Per-step draws: real and imaginary parts of the four white noises' complex envelopes.
N_NOISE_ENV = 8

STATE = Layout([
    ("zr", (N_CORE,)), ("zi", (N_CORE,)), ("s_pd", (2,)), ("integ_pll", ()), ("v_tune", ()),
    ("s_amp", (2,)), ("integ", ()), ("u", ()), ("n", ()),
    ("pd", ()), ("amp", ()), ("ri", ()), ("rq", ()), ("s_i", (2,)), ("s_q", (2,)), ("t", ()),
    ("acc_rate", ()), ("acc_quad", ()), ("acc_amp", ()), ("acc_u", ()), ("acc_f", ()), ("acc_tune", ()),
])

PARAMS = Layout([
    ("Phi", (N_CORE, N_CORE)), ("Gr", (N_CORE,)), ("Gi", (N_CORE,)), ("Gr_w", (N_CORE,)), ("Gi_w", (N_CORE,)),
    ("w0", ()), ("Nr", (N_CORE, 4)), ("Ni", (N_CORE, 4)),
    ("C_vx", (N_CORE,)), ("C_vs", (N_CORE,)),
] + PHASE_LOOP_FIELDS + SMOOTHING_FIELDS + CONTROLLER_FIELDS + MODULATOR_FIELDS + [  # the two loops'
] + OUTPUT_FIELDS + [("h", ())])


def detector_readings(zr, zi, p, ops=numpy_ops):
    """Phase detector, amplitude channel, rate and quadrature products of the envelope ``zr + j zi``.

    Parameters
    ----------
    zr, zi : sequence
        Real and imaginary parts of the core's envelope.
    p : sequence
        Parameters laid out as :data:`PARAMS`.
    ops : object, optional
        Math backend.

    Returns
    -------
    list
        ``[pd, amp, rate product, quadrature product]`` (before the low-passes).
    """
    P = PARAMS.unpack
    vr, vi = dot(P(p, "C_vx"), zr), dot(P(p, "C_vx"), zi)
    sr, si = dot(P(p, "C_vs"), zr), dot(P(p, "C_vs"), zi)
    pc, ps = P(p, "pd_cos"), P(p, "pd_sin")
    c, s = P(p, "cos_ref"), P(p, "sin_ref")
    half = 0.5 * P(p, "k_demod") * P(p, "vdac")
    return [vr * pc + vi * ps, P(p, "k_amp") * (vr * ps - vi * pc), half * (sr * c + si * s), half * (sr * s - si * c)]


def step(x, p, w, ops=numpy_ops):
    """Advance the PLL drive's envelope by one step.

    Parameters
    ----------
    x : sequence
        State laid out as :data:`STATE`.
    p : sequence
        Parameters laid out as :data:`PARAMS`.
    w : sequence
        Standard-normal draws (length :data:`N_NOISE_ENV`).
    ops : object, optional
        Math backend.

    Returns
    -------
    list
        The next state.
    """
    S, P = STATE.unpack, PARAMS.unpack
    h = P(p, "h")
    u, v_tune = S(x, "u"), S(x, "v_tune")
    omega = 2 * np.pi * (P(p, "f_free") + P(p, "k_vco") * v_tune)
    dw = omega - P(p, "w0")
    agc = AmplitudeLoopStep(PARAMS, p)
    a = agc.modulator_gain(u, P(p, "vdac"))
    Phi = P(p, "Phi")
    yr, yi = matvec(Phi, S(x, "zr")), matvec(Phi, S(x, "zi"))
    Gr, Gi, Gr_w, Gi_w = P(p, "Gr"), P(p, "Gi"), P(p, "Gr_w"), P(p, "Gi_w")
    yr = [yr[k] + a * (Gr[k] + dw * Gr_w[k]) for k in range(N_CORE)]
    yi = [yi[k] + a * (Gi[k] + dw * Gi_w[k]) for k in range(N_CORE)]
    cr, sr = ops.cos(omega * h), ops.sin(omega * h)  # e^{-j w h} = cr - j sr
    nr = matvec(P(p, "Nr"), list(w[:4]))
    ni = matvec(P(p, "Ni"), list(w[:4]))
    nr2 = matvec(P(p, "Nr"), list(w[4:]))
    ni2 = matvec(P(p, "Ni"), list(w[4:]))
    # noise: (Nr + j Ni) (w_re + j w_im)
    zr1 = [cr * yr[k] + sr * yi[k] + nr[k] - ni2[k] for k in range(N_CORE)]
    zi1 = [cr * yi[k] - sr * yr[k] + ni[k] + nr2[k] for k in range(N_CORE)]
    pd1, amp1, ri1, rq1 = detector_readings(zr1, zi1, p, ops)
    # step means by the trapezoid rule, as the carrier step's demodulators take them
    s_pd, integ_pll1, v_tune1 = regulate_phase(P, p, S(x, "s_pd"), S(x, "integ_pll"), 0.5 * (S(x, "pd") + pd1), h, ops)
    s_amp, integ1, u1 = agc.regulate(S(x, "s_amp"), S(x, "integ"), 0.5 * (S(x, "amp") + amp1), h, ops)
    s_i = _lpf_step(P(p, "Phi_out"), P(p, "Gam_out"), S(x, "s_i"), 0.5 * (S(x, "ri") + ri1))
    s_q = _lpf_step(P(p, "Phi_out"), P(p, "Gam_out"), S(x, "s_q"), 0.5 * (S(x, "rq") + rq1))
    acc = [S(x, "acc_rate") + s_i[0], S(x, "acc_quad") + s_q[0], S(x, "acc_amp") + s_amp[0], S(x, "acc_u") + u1,
           S(x, "acc_f") + omega / (2 * np.pi), S(x, "acc_tune") + v_tune1]
    return (zr1 + zi1 + s_pd + [integ_pll1, v_tune1] + s_amp + [integ1, u1, S(x, "n"), pd1, amp1, ri1, rq1]
            + s_i + s_q + [S(x, "t") + h] + acc)


#: The PLL drive's envelope step as a compilable model.
PLL_ENVELOPE_MODEL = StepModel("fmvmg_pll_envelope", STATE, PARAMS, N_NOISE_ENV, step,
                               reset=("acc_rate", "acc_quad", "acc_amp", "acc_u", "acc_f", "acc_tune"))

__all__ = ["STATE", "PARAMS", "N_NOISE_ENV", "step", "detector_readings", "PLL_ENVELOPE_MODEL"]
