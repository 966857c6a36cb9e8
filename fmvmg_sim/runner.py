"""Run a scenario with the engine its fidelity asks for, and summarise it."""

from __future__ import annotations

import numpy as np

from . import thermal_laws as law
from .averaged import scale_factor_V_per_dps, steady_state
from .diagram import build_diagram
from .result import SimResult
from .scenario import Scenario
from .summary import summarize


def vref_profile_V(scn: Scenario, t_s: np.ndarray, temperature_C: np.ndarray) -> np.ndarray:
    """The AGC set-point (V) at each sample: Vref(T) times the scenario's set-point factor.

    Parameters
    ----------
    scn : Scenario
    t_s, temperature_C : ndarray

    Returns
    -------
    ndarray
    """
    ref = scn.device.values["circuit"]["reference"]
    dT = np.asarray(temperature_C) - scn.device.reference_temperature_C
    return law.linear_tc(ref["vref_V"], dT, ref["vref_tc_per_K"]) * np.asarray(scn.vref_factor(t_s))


def predictions(scn: Scenario, temperature_C: float) -> dict:
    """Analytic (averaged-model) steady state at ``temperature_C``, for reports.

    Parameters
    ----------
    scn : Scenario
    temperature_C : float

    Returns
    -------
    dict
    """
    dg = build_diagram(scn.device, temperature_C)
    ss = steady_state(dg)
    sf = scale_factor_V_per_dps(dg)
    return dict(temperature_C=float(temperature_C), drive_frequency_Hz=ss.f_Hz, drive_amplitude_m=ss.amplitude_m,
                agc_effort_V=ss.agc_effort_V, scale_factor_V_per_dps=sf, zero_rate_bias_dps=ss.rate_V / sf,
                loop_phase_error_rad=ss.loop_phase_error_rad, quadrature_V=ss.quadrature_V)


def run_scenario(scn: Scenario, progress: bool | None = None) -> tuple[SimResult, dict]:
    """Simulate ``scn`` and summarise it.

    Parameters
    ----------
    scn : Scenario
    progress : bool, optional
        Progress bar on stderr (default: for runs expected to take more than a few seconds).

    Returns
    -------
    tuple
        (SimResult, summary dict)
    """
    if scn.fidelity() == "carrier":
        from .carrier.engine import run_carrier
        res = run_carrier(scn, progress=progress)
    else:
        from .envelope.engine import run_envelope
        res = run_envelope(scn, progress=progress)
    t = res.time_s
    vref = vref_profile_V(scn, t, res["temperature_C"])
    me = scn.device.values["mechanics"]
    ring_s = 2 * me["q_sense"] / (2 * np.pi * me["f_sense_Hz"])
    summary = summarize(res, vref, scn.device.values["circuit"]["pi"]["u_max_V"],
                        predicted=predictions(scn, float(res["temperature_C"][-1])),
                        transient_s=3 * ring_s, by_temperature_predicted=lambda T: predictions(scn, T))
    return res, summary
