"""The PLL drive's diagram as one carrier-level step function, built from the blocks' faces.

The linear core (resonator, pickoffs, amplifiers, comb drive; no phase shifter, modulator gain
zero) is advanced exactly for the oscillator's drive ``v_ac = K_mod u Vdac cos(theta)``: over a
step the oscillator's phase advances at a held frequency ``w``, and the response to that
sinusoid is the top-right block of ``exp([[A, b e1'], [0, W(w)]] h)`` (``W`` the 2x2 rotation
generator), scheduled to first order in ``w - w0`` (``w0`` the lock frequency). The phase itself
is advanced exactly (:meth:`blocks.nco.ControlledOscillator.carrier_step`), so a frequency offset
does not build up an amplitude error. The phase detector and the amplitude channel are
demodulators (step means by the trapezoid rule), each followed by its low-pass; the loop filter
and the AGC are PI controllers with anti-windup.
"""

from __future__ import annotations

import numpy as np

from blocks import Multiplier
from blocks.nco import ControlledOscillator
from blocks.ops import numpy_ops
from blocks.phase_detector import QuadratureDetector

from ..amplitude_loop import CONTROLLER_FIELDS, MODULATOR_FIELDS, SMOOTHING_FIELDS, AmplitudeLoopStep
from ..compiled import StepModel
from ..pll_drive import PHASE_LOOP_FIELDS, regulate_phase
from ..numerics.layout import Layout, dot, lpf_step as _lpf_step, matvec
from .step import N_CORE, N_NOISE, OUTPUT_FIELDS

STATE = Layout([
    ("z", (N_CORE,)), ("theta", ()), ("s_pd", (2,)), ("integ_pll", ()), ("v_tune", ()),
    ("s_amp", (2,)), ("integ", ()), ("u", ()), ("n", ()),
    ("vx", ()), ("vs", ()), ("s_i", (2,)), ("s_q", (2,)), ("fq", ()), ("t", ()),
    ("acc_rate", ()), ("acc_quad", ()), ("acc_amp", ()), ("acc_u", ()), ("acc_f", ()), ("acc_tune", ()),
])

PARAMS = Layout([
    ("Phi", (N_CORE, N_CORE)), ("G", (N_CORE, 2)), ("G_w", (N_CORE, 2)), ("w0", ()),
    ("Gam_fx", (N_CORE,)), ("Gam_w", (N_CORE, N_NOISE)),
    ("C_vx", (N_CORE,)), ("C_vs", (N_CORE,)), ("off_vx", ()), ("off_vs", ()),
] + PHASE_LOOP_FIELDS + SMOOTHING_FIELDS + CONTROLLER_FIELDS + MODULATOR_FIELDS + [  # the two loops'
    ("quad_coef", ()), ("vdc2", ()),
] + OUTPUT_FIELDS + [("h", ())])


def step(x, p, w, ops=numpy_ops):
    """Advance the PLL-driven diagram by one step.

    Parameters
    ----------
    x : sequence
        State laid out as :data:`STATE`.
    p : sequence
        Parameters laid out as :data:`PARAMS`.
    w : sequence
        Standard-normal draws for this step (length :data:`N_NOISE`).
    ops : object, optional
        Math backend (numpy or CasADi).

    Returns
    -------
    list
        The next state.
    """
    S, P = STATE.unpack, PARAMS.unpack
    z, h = S(x, "z"), P(p, "h")
    u, v_tune, theta = S(x, "u"), S(x, "v_tune"), S(x, "theta")
    vx0, vs0 = S(x, "vx"), S(x, "vs")
    nco = ControlledOscillator(f_free_Hz=P(p, "f_free"), k_vco_Hz_per_V=1.0)
    nco.k_vco_Hz_per_V = P(p, "k_vco")  # set after construction: symbolic under CasADi
    omega = nco.omega_rad_s(v_tune)
    c0, s0 = ops.cos(theta), ops.sin(theta)
    # --- linear core driven by v_ac = K_mod u Vdac cos(theta), the oscillator at a held frequency --------
    G, G_w = P(p, "G"), P(p, "G_w")
    dw = omega - P(p, "w0")
    agc = AmplitudeLoopStep(PARAMS, p)
    a = agc.modulator_gain(u, P(p, "vdac"))
    lin = matvec(P(p, "Phi"), z)
    wn = matvec(P(p, "Gam_w"), list(w))
    Gfx, fq = P(p, "Gam_fx"), S(x, "fq")
    z1 = [lin[i] + a * ((G[i][0] + dw * G_w[i][0]) * c0 + (G[i][1] + dw * G_w[i][1]) * s0) + wn[i] + Gfx[i] * fq
          for i in range(N_CORE)]
    vx1 = dot(P(p, "C_vx"), z1) + P(p, "off_vx")
    vs1 = dot(P(p, "C_vs"), z1) + P(p, "off_vs")
    theta1, c1, s1 = nco.carrier_step(theta, v_tune, h, ops)
    # --- phase detector and amplitude channel on v_x ------------------------------------------------
    det = QuadratureDetector(k_pd=1.0, k_amp=P(p, "k_amp"))
    pc, ps = P(p, "pd_cos"), P(p, "pd_sin")  # the detector's trim as cos and sin
    pd, amp = det.carrier_mean(vx0, vx1, c0 * pc - s0 * ps, s0 * pc + c0 * ps, c1 * pc - s1 * ps,
                               s1 * pc + c1 * ps)
    s_pd, integ_pll1, v_tune1 = regulate_phase(P, p, S(x, "s_pd"), S(x, "integ_pll"), pd, h, ops)
    s_amp, integ1, u1 = agc.regulate(S(x, "s_amp"), S(x, "integ"), amp, h, ops)
    # --- rate and quadrature demodulated against the oscillator --------------------------------------
    c, s = P(p, "cos_ref"), P(p, "sin_ref")
    vd = P(p, "vdac")
    ri0, ri1 = vd * (c0 * c - s0 * s), vd * (c1 * c - s1 * s)
    rq0, rq1 = vd * (s0 * c + c0 * s), vd * (s1 * c + c1 * s)
    demod = Multiplier(k_per_V=P(p, "k_demod"))
    s_i = _lpf_step(P(p, "Phi_out"), P(p, "Gam_out"), S(x, "s_i"), demod.carrier_mean(vs0, vs1, ri0, ri1))
    s_q = _lpf_step(P(p, "Phi_out"), P(p, "Gam_out"), S(x, "s_q"), demod.carrier_mean(vs0, vs1, rq0, rq1))
    # --- quadratic comb force held over the next step -------------------------------------------------
    vac1 = agc.modulator_gain(u1, vd) * c1
    fq1 = P(p, "quad_coef") * (P(p, "vdc2") + vac1 * vac1)
    acc = [S(x, "acc_rate") + s_i[0], S(x, "acc_quad") + s_q[0], S(x, "acc_amp") + s_amp[0], S(x, "acc_u") + u1,
           S(x, "acc_f") + omega / (2 * np.pi), S(x, "acc_tune") + v_tune1]
    return (z1 + [theta1] + s_pd + [integ_pll1, v_tune1] + s_amp + [integ1, u1, S(x, "n"), vx1, vs1] + s_i + s_q
            + [fq1, S(x, "t") + h] + acc)


#: The PLL drive's carrier step as a compilable model.
PLL_CARRIER_MODEL = StepModel("fmvmg_pll_carrier", STATE, PARAMS, N_NOISE, step,
                              reset=("acc_rate", "acc_quad", "acc_amp", "acc_u", "acc_f", "acc_tune"))

__all__ = ["STATE", "PARAMS", "step", "PLL_CARRIER_MODEL"]
