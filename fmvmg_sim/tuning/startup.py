"""Large-signal start-up of the amplitude loop on the averaged model (PI clamp and anti-windup included).

Start-up is not a small-signal event: the PI output sits at ``u_max`` while the amplitude
grows, and the integrator is held by the PI block's anti-windup. The linearised loop
says nothing about it, so the tuning check predicts it with the averaged amplitude
dynamics of :mod:`.linear_loop` made nonlinear where the loop is:

* ``A' = -A/tau_d + b(A) u``: for the 'normalized' carrier ``b(A) = b min(1, a(A)/floor)``
  because the carrier normaliser divides by ``max(sqrt(v_x^2 + v_ps^2), floor)``
  (floor = :data:`fmvmg_sim.amplitude_loop.NORMALISER_FLOOR_REL` times the steady ``v_ps``
  amplitude); for the 'pickoff' carrier ``b(A) = b A / A_0``;
* the rectifier by its describing function, ``sensor_gain * A`` (+ rectifier offset);
* the low-pass, comparator and PI: the amplitude loop's step face
  (:meth:`fmvmg_sim.amplitude_loop.AmplitudeLoop.regulator`), the same clamp and conditional
  integration the carrier engine runs.
"""

from __future__ import annotations

import numpy as np

from ..amplitude_loop import NORMALISER_FLOOR_REL
from ..diagram import Diagram
from .linear_loop import PlantParameters, plant_parameters, with_gains


def averaged_startup(dg: Diagram, kp: float, ki_per_s: float, duration_s: float, amplitude0_m: float = 10e-9,
                     step_s: float = 2e-5, params: PlantParameters | None = None) -> dict:
    """Simulate the averaged amplitude loop from rest.

    Parameters
    ----------
    dg : Diagram
    kp, ki_per_s : float
        PI gains.
    duration_s : float
    amplitude0_m : float, optional
        Initial drive amplitude (the start-up perturbation).
    step_s : float, optional
        Integration step (exact for A and the low-pass with u held over the step).
    params : PlantParameters, optional

    Returns
    -------
    dict
        ``t_s``, ``r_V``, ``u_V``, ``amplitude_m`` arrays and ``vref_V``.
    """
    p = params or plant_parameters(dg)
    n = int(np.ceil(duration_s / step_s))
    h = step_s
    loop = dg.amplitude_loop.regulator(h, with_gains(dg, kp, ki_per_s))
    decay = np.exp(-p.plant_pole_rad_s * h)
    gain_h = (1 - decay) / p.plant_pole_rad_s if p.plant_pole_rad_s > 0 else h
    w = p.omega_rad_s
    chain_m = abs(dg.drive_chain_response(w))          # |v_x| per metre
    vps_m = abs(dg.drive_chain_response(w) * dg.phase_shifter_response(w))
    floor_V = NORMALISER_FLOOR_REL * vps_m * p.amplitude_m
    offset = dg.rectifier.offset_V
    A, s, integ, u = float(amplitude0_m), np.zeros(2), 0.0, 0.0
    t_out = (np.arange(n) + 1) * h
    r_out, u_out, a_out = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        if p.carrier_mode == "normalized":
            # sqrt(v_x^2 + v_ps^2) is constant (= their amplitude) for v_x, v_ps in quadrature and of
            # equal size (unit-gain all-pass); the rms of the two amplitudes covers a small mismatch
            amp_V = np.hypot(chain_m * A, vps_m * A) / np.sqrt(2.0)
            bA = p.b_m_per_V_s * min(1.0, amp_V / floor_V)
        else:
            bA = p.b_m_per_V_s * A / p.amplitude_m
        A = A * decay + bA * u * gain_h
        s, integ, u = loop.regulate(s, integ, p.sensor_gain_V_per_m * A + offset, h)
        r_out[k], u_out[k], a_out[k] = s[0], u, A
    return dict(t_s=t_out, r_V=r_out, u_V=u_out, amplitude_m=a_out, vref_V=dg.vref_V)
