"""A unit's figures of merit, read from its run's summary and its rate output.

* ``bias_25C_dps``: the zero-rate bias on the hold at the device's reference temperature (the summary's
  ``by_temperature`` row; the whole run's bias when the run has one temperature);
* ``bias_tc_dps_per_K``: the least-squares slope of the holds' biases against their temperatures;
* ``bias_span_dps``: the largest minus the smallest hold bias (the bias over temperature);
* ``scale_factor_V_per_dps``: the scale factor at the reference temperature (measured on an applied rate when
  the scenario applies one, else the averaged model's value at each hold, as the summary reports it);
* ``scale_factor_tc_ppm_per_K``: the slope of the holds' scale factors, relative to the reference value;
* ``arw_deg_per_sqrt_h``, ``bias_instability_deg_per_h``: the Allan analysis (:mod:`fmvmg_sim.analysis.allan`)
  of the rate over the first stretch at constant temperature and rate;
* ``startup_time_s``: the drive amplitude's settling time, reported when the run starts from rest.

A figure the run cannot give (one temperature for a coefficient, no white-noise region for the ARW) is NaN.
"""

from __future__ import annotations

import numpy as np

from ..analysis.allan import allan_deviation
from ..errors import InputError
from ..result import SimResult

#: Figures of merit, with their meaning (for the spec file's documentation and the report).
FIGURES = {
    "bias_25C_dps": "zero-rate bias at the reference temperature (deg/s)",
    "bias_tc_dps_per_K": "bias temperature coefficient, slope over the holds (deg/s/K)",
    "bias_span_dps": "largest minus smallest hold bias (deg/s)",
    "scale_factor_V_per_dps": "scale factor at the reference temperature (V/(deg/s))",
    "scale_factor_tc_ppm_per_K": "scale-factor temperature coefficient, relative slope (ppm/K)",
    "arw_deg_per_sqrt_h": "angle random walk (deg/sqrt(h))",
    "bias_instability_deg_per_h": "bias instability, the Allan minimum (deg/h)",
    "startup_time_s": "drive start-up time to within 1 % of the set-point (s)",
}

#: Shortest stretch (samples) the Allan analysis is run on.
MIN_ALLAN_SAMPLES = 64


def figures_of_merit(res: SimResult, summary: dict, reference_C: float, from_rest: bool) -> dict:
    """The figures of :data:`FIGURES` of one run.

    Parameters
    ----------
    res : SimResult
    summary : dict
        The run's summary (:func:`fmvmg_sim.summary.summarize`).
    reference_C : float
        The device's reference temperature.
    from_rest : bool
        Whether the run starts from rest (else the start-up time is NaN).

    Returns
    -------
    dict
        ``{figure: float}``, NaN where the run cannot give it.
    """
    nan = float("nan")
    rows = summary.get("by_temperature") or []
    out = dict.fromkeys(FIGURES, nan)
    if rows:
        T = np.array([r["temperature_C"] for r in rows])
        bias = np.array([_num(r["zero_rate_bias_dps"]) for r in rows])
        sf = np.array([_num(r["scale_factor_V_per_dps"]) if np.isfinite(_num(r["scale_factor_V_per_dps"]))
                       else _num((r.get("predicted") or {}).get("scale_factor_V_per_dps")) for r in rows])
        ref = int(np.argmin(np.abs(T - reference_C)))
        out["bias_25C_dps"] = bias[ref]
        out["scale_factor_V_per_dps"] = sf[ref]
        ok = np.isfinite(bias)
        if ok.sum() >= 2:
            out["bias_tc_dps_per_K"] = float(np.polyfit(T[ok], bias[ok], 1)[0])
            out["bias_span_dps"] = float(np.ptp(bias[ok]))
        ok = np.isfinite(sf)
        if ok.sum() >= 2 and np.isfinite(sf[ref]) and sf[ref] != 0:
            out["scale_factor_tc_ppm_per_K"] = float(np.polyfit(T[ok], sf[ok], 1)[0] / sf[ref] * 1e6)
    else:
        out["bias_25C_dps"] = _num(summary.get("zero_rate_bias_dps"))
        sf = _num(summary.get("scale_factor_V_per_dps"))
        out["scale_factor_V_per_dps"] = sf if np.isfinite(sf) else _num(
            (summary.get("predicted") or {}).get("scale_factor_V_per_dps"))
    out.update(_allan_figures(res))
    if from_rest:
        out["startup_time_s"] = _num(summary.get("settling_time_s"))
    return {k: float(v) for k, v in out.items()}


def _num(v) -> float:
    return float("nan") if v is None else float(v)


def _allan_figures(res: SimResult) -> dict:
    """ARW and bias instability over the first stretch at constant temperature and rate."""
    t = res.time_s
    change = np.flatnonzero((np.diff(res["temperature_C"]) != 0) | (np.diff(res["rate_true_dps"]) != 0))
    end = int(change[0]) + 1 if change.size else len(t)
    rate = res["rate_dps"][:end]
    rate = rate[np.isfinite(rate)]
    nan = float("nan")
    if rate.size < MIN_ALLAN_SAMPLES or len(t) < 2:
        return {"arw_deg_per_sqrt_h": nan, "bias_instability_deg_per_h": nan}
    try:
        a = allan_deviation(rate, 1.0 / float(np.median(np.diff(t))))
    except InputError:
        return {"arw_deg_per_sqrt_h": nan, "bias_instability_deg_per_h": nan}
    return {"arw_deg_per_sqrt_h": _num(a.arw_deg_per_sqrt_h),
            "bias_instability_deg_per_h": _num(a.bias_instability_deg_per_h)}
