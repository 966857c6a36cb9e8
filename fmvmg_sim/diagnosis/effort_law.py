"""A calibration start from the AGC effort's own temperature law.

In the amplitude loop's steady state the drive force balances the drive mode's damping, so the AGC effort is the
drive damping ``1/Q(T)`` times what the loop holds fixed (amplitude, transduction), as recorded through its channel
(offset, gain, gain drift). Its curve over temperature is drawn by seven knobs, the Q law's four (level, solid
share, gas exponent, curvature) and the channel's three, which trade against each other: the record fixes the
curve, not each knob. In the whole calibration the effort's few microvolts of noise make those trades products of
deviations far larger than the noise, and Levenberg-Marquardt steps from the nominal unit stop in a corner where
the effort's gain drift sits at its bound in place of the law's shape. Alone, the curve is a small, smooth fit:
:func:`effort_law_start` makes it over the training blocks with the other knobs where a calibration left them, and
the calibration starts again from there.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..thermal_laws import quality_factor_law
from ..uncertainty import KNOBS_BY_NAME
from .forward import CHANNELS
from .parameters import deviated

#: The Q law's knobs (the drive mode's level and the law's shape).
LAW_KNOBS = ("q_drive_rel", "q_solid_damping_rel", "q_gas_exponent", "q_curvature_per_K2")
#: The recorded effort's channel knobs.
CHANNEL_KNOBS = ("agc_effort_offset_V", "agc_effort_gain_rel", "agc_effort_tc_per_K")


def drive_damping(device, theta: dict, temperature_C: np.ndarray) -> np.ndarray:
    """``1/Q`` of the drive mode at die temperatures, with the Q law's knobs at ``theta``.

    Parameters
    ----------
    device : Device
        The data-sheet device (deviations are relative to it).
    theta : dict
        Deviations of :data:`LAW_KNOBS` (missing ones nominal).
    temperature_C : ndarray

    Returns
    -------
    ndarray
    """
    th = dict(device.values["thermal"])
    th["q_drive"] = device.values["mechanics"]["q_drive"]
    for name in LAW_KNOBS:
        k = KNOBS_BY_NAME[name]
        for path in k.paths:
            th[path[-1]] = deviated(k.kind, th.get(path[-1], 0.0), theta.get(name, 0.0))
    return 1.0 / quality_factor_law(th["q_drive"], temperature_C, device.reference_temperature_C, th["q_ted"],
                                    th["q_anchor"], th["q_gas_exponent"], th.get("q_extra_tc_per_K", 0.0),
                                    th.get("q_curvature_per_K2", 0.0))


def fit_effort_law(device, knobs, theta: dict, temperature_C, case_dT_K, effort_V, sigma_V, unit_effort) -> dict:
    """The Q law's and the effort channel's knobs that fit the recorded effort best, within their priors.

    The model of the recorded effort is ``o + (1 + g)(1 + tc dT_case) u / Q(T)``; the fit starts from ``theta``
    (with the gain drift at 0: at its bound it is the symptom this start is for) and from the law's gas-only end
    (the solid damping at its lower bound), bounded as the calibration is, and keeps the better.

    Parameters
    ----------
    device : Device
        The data-sheet device.
    knobs : KnobSet
        The calibrated knobs (their tolerances and bounds).
    theta : dict
        Where a calibration left the knobs.
    temperature_C, case_dT_K : ndarray
        Each block's die temperature and its case temperature from the reference (the channel's drift).
    effort_V, sigma_V : ndarray
        The recorded effort and its block noise.
    unit_effort : ndarray
        The model's effort per unit drive damping (its effort times Q) on each block.

    Returns
    -------
    dict
        ``{knob: deviation}`` of :data:`LAW_KNOBS` and :data:`CHANNEL_KNOBS`.
    """
    names = LAW_KNOBS + CHANNEL_KNOBS
    idx = [knobs.names.index(n) for n in names]
    tol, lo, hi = knobs.tolerance[idx], knobs.lo[idx], knobs.hi[idx]
    n_law = len(LAW_KNOBS)

    def residuals(x):
        o, g, tc = x[n_law:]
        pred = o + (1.0 + g) * (1.0 + tc * case_dT_K) * unit_effort * drive_damping(
            device, dict(zip(LAW_KNOBS, x[:n_law])), temperature_C)
        return np.concatenate([(effort_V - pred) / sigma_V, x / tol])

    x0 = np.array([theta.get(n, 0.0) for n in names])
    x0[names.index("agc_effort_tc_per_K")] = 0.0
    gas_end = x0.copy()
    gas_end[names.index("q_solid_damping_rel")] = lo[names.index("q_solid_damping_rel")]
    inside = (hi - lo) * 1e-9
    fits = [least_squares(residuals, np.clip(s, lo + inside, hi - inside), bounds=(lo, hi), x_scale=tol,
                          method="trf") for s in (x0, gas_end)]
    best = min(fits, key=lambda r: r.cost)
    return dict(zip(names, map(float, best.x)))


def effort_law_start(fitter, cal, rows: np.ndarray) -> dict | None:
    """A calibration start: ``cal``'s knobs with the Q law and the effort channel refitted to the effort alone.

    Parameters
    ----------
    fitter : Fitter
        The fitter ``cal`` was made with.
    cal : Calibration
    rows : ndarray of bool
        Training blocks.

    Returns
    -------
    dict or None
        ``{knob: deviation}``; None when the record has no effort or the device no Q-law knobs.
    """
    ci = CHANNELS.index("agc_effort_V")
    if not fitter.present[ci] or any(n not in fitter.knobs.names for n in LAW_KNOBS + CHANNEL_KNOBS):
        return None
    path = fitter.path(None)
    die_C = path["die_b"]
    raw = cal.base.evaluate(die_C, path["rate_b"], path["quad_b"])[:, ci]
    y, s, dT = fitter.Y[:, ci], fitter.S[:, ci], fitter.case_dT_K
    ok = rows & np.isfinite(y) & np.isfinite(raw) & np.isfinite(die_C) & (s > 0)
    if ok.sum() < 2 * (len(LAW_KNOBS) + len(CHANNEL_KNOBS)):
        return None
    unit = raw[ok] / drive_damping(fitter.device0, cal.theta, die_C[ok])
    start = dict(cal.theta)
    start.update(fit_effort_law(fitter.device0, fitter.knobs, cal.theta, die_C[ok], dT[ok], y[ok], s[ok], unit))
    return start
