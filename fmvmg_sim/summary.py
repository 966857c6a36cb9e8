"""Summary of a run: steady drive amplitude and frequency, settling, scale factor, bias, loop health."""

from __future__ import annotations

import numpy as np

from .result import SimResult

#: Band around the set-point within which the drive amplitude counts as settled.
SETTLE_BAND = 0.01


def settling_time_s(t: np.ndarray, y: np.ndarray, target: np.ndarray | float, band: float = SETTLE_BAND) -> float:
    """First time after which ``y`` stays within ``band`` (relative) of ``target``; NaN if never.

    Parameters
    ----------
    t, y : ndarray
    target : float or ndarray
    band : float, optional

    Returns
    -------
    float
    """
    target = np.broadcast_to(np.asarray(target, dtype=float), y.shape)
    outside = np.abs(y - target) > band * np.abs(target)
    if not outside.any():
        return float(t[0])
    last = np.flatnonzero(outside)[-1]
    return float(t[last + 1]) if last + 1 < len(t) else float("nan")


def summarize(res: SimResult, vref_V: np.ndarray, u_max_V: float, predicted: dict | None = None,
              transient_s: float = 0.0, by_temperature_predicted=None) -> dict:
    """Steady-state figures and loop health of a run.

    Parameters
    ----------
    res : SimResult
    vref_V : ndarray
        The amplitude set-point at each sample (V).
    u_max_V : float
        Upper limit of the PI output.
    predicted : dict, optional
        Analytic predictions to report beside the simulated values.
    transient_s : float, optional
        Samples this long after a change of applied rate or temperature are left out
        of the scale-factor and bias estimates (the open-loop sense mode rings for
        about 3 x 2 Q_s / w_s).
    by_temperature_predicted : callable, optional
        ``f(T) -> dict`` of predictions, reported beside each temperature hold.

    Returns
    -------
    dict
        JSON-ready summary; ``status`` is ``ok``, ``no_oscillation``, ``saturated`` or
        ``not_settled`` and ``messages`` explains anything but ``ok``.
    """
    t = res.time_s
    n = len(t)
    tail = slice(max(0, n - max(1, n // 10)), n)
    amp = res["drive_amplitude_V"]
    u = res["agc_effort_V"]
    f = res["drive_frequency_Hz"]
    settle = settling_time_s(t, amp, vref_V)
    msgs = []
    status = "ok"
    if np.nanmean(amp[tail]) < 0.1 * np.mean(vref_V[tail]):
        status = "no_oscillation"
        msgs.append("the drive loop did not start: amplitude below 10 % of the set-point at the end")
    elif np.all(u[tail] >= u_max_V * (1 - 1e-9)):
        status = "saturated"
        msgs.append(f"the AGC output is saturated at {u_max_V} V: the set-point is out of reach")
    elif not np.isfinite(settle):
        status = "not_settled"
        msgs.append(f"the drive amplitude is not within {SETTLE_BAND:.0%} of the set-point at the end of the run")
    settled = t >= (settle if np.isfinite(settle) else t[-1])
    true = res["rate_true_dps"]
    temp = res["temperature_C"]
    quiet = settled & _quiet(t, true, temp, transient_s)
    sf, sf_source, bias = _sf_and_bias(true, res["rate_V"], res["rate_dps"], quiet)
    groups = []
    holds = np.unique(np.round(temp[quiet], 6))
    if len(holds) > 1 and len(holds) <= 20:
        for T in holds:
            m = quiet & (np.round(temp, 6) == T)
            g_sf, _, g_bias = _sf_and_bias(true, res["rate_V"], res["rate_dps"], m)
            row = dict(temperature_C=float(T), scale_factor_V_per_dps=g_sf, zero_rate_bias_dps=g_bias,
                       samples=int(m.sum()))
            if by_temperature_predicted is not None:
                row["predicted"] = by_temperature_predicted(float(T))
            groups.append(row)
    ff = f[tail][np.isfinite(f[tail])]
    out = dict(
        status=status, messages=msgs, engine=res.info.get("engine"),
        drive_amplitude_V=float(np.nanmean(amp[tail])), drive_amplitude_setpoint_V=float(np.mean(vref_V[tail])),
        drive_amplitude_m=float(np.nanmean(res.internal["drive_displacement_amplitude_m"][tail]))
        if "drive_displacement_amplitude_m" in res.internal else None,
        drive_frequency_Hz=float(np.mean(ff)) if ff.size else float("nan"),
        agc_effort_V=float(np.nanmean(u[tail])), settling_time_s=settle,
        scale_factor_V_per_dps=sf, scale_factor_source=sf_source,
        nominal_scale_factor_V_per_dps=res.info.get("nominal_scale_factor_V_per_dps"),
        zero_rate_bias_dps=bias, transient_excluded_s=transient_s,
        wall_time_s=res.info.get("wall_time_s"), simulated_time_s=res.info.get("simulated_time_s"),
        steps_per_cycle=res.info.get("steps_per_cycle"),
    )
    if groups:
        out["by_temperature"] = groups
    if predicted:
        out["predicted"] = predicted
    return out


def _quiet(t: np.ndarray, true: np.ndarray, temp: np.ndarray, transient_s: float) -> np.ndarray:
    """Samples at least ``transient_s`` after the last change of applied rate or temperature."""
    change = np.zeros(len(t), dtype=bool)
    change[1:] = (np.diff(true) != 0) | (np.diff(temp) != 0)
    last_change = np.maximum.accumulate(np.where(change, t, -np.inf))
    return (t - last_change) >= transient_s


def _sf_and_bias(true, rate_V, rate_dps, use):
    use = use & np.isfinite(rate_V)
    sf, src, bias = float("nan"), "none", float("nan")
    if use.sum() > 10 and np.ptp(true[use]) > 0:
        Afit = np.column_stack([true[use], np.ones(use.sum())])
        sf = float(np.linalg.lstsq(Afit, rate_V[use], rcond=None)[0][0])
        src = "least squares of rate_V on rate_true_dps over settled samples away from rate/temperature changes"
    zero = use & (true == 0)
    if zero.sum() > 0:
        bias = float(np.mean(rate_dps[zero]))
    return sf, src, bias
