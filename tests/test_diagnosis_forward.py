"""The quasi-static forward model against the envelope engine (noise off, effects on)."""

import numpy as np

from fmvmg_sim.diagnosis.forward import CHANNELS, predict_device
from tests.test_diagnosis_helpers import oven_record

# tolerances per channel (the model floors of fmvmg_sim.diagnosis.data.FLOORS are about 3x above these)
TOL = {"rate_V": 1e-6, "quadrature_V": 5e-6, "drive_amplitude_V": 1e-6, "agc_effort_V": 3e-6,
       "drive_frequency_Hz": 1e-4}


def test_forward_matches_envelope_with_effects(tmp_path):
    eff = {"thermal_lag": {"tau_s": 600.0, "offset_K": 0.5}, "demod_phase_drift": {"kappa_urad_per_K": 100.0},
           "thermal_hysteresis": {"quad_rel": 0.01, "width_K": 10.0},
           "temperature_rate": {"g_dph_per_K_per_min": 50.0}, "q_factor_drift": {"q_tc_per_K": 0.004}}
    rec, res = oven_record(tmp_path, "fw", eff, noise=False)
    from fmvmg_sim.scenario import load_scenario
    scn = load_scenario(tmp_path / "fw.toml")
    t = res.time_s
    dt = t[1] - t[0]
    # each sample is the mean over the interval ending at its time stamp: evaluate at the centre
    Tc = np.interp(t - dt / 2, t, res["temperature_C"])
    p = predict_device(scn.device_nominal, scn.effects, t - dt / 2, Tc, res["rate_true_dps"])
    assert np.max(np.abs(p["die_temperature_C"] - res["die_temperature_C"])) < 0.02
    for c in CHANNELS:
        err = np.max(np.abs(res[c][30:] - p[c][30:]))
        assert err < TOL[c], (c, err)
    # the effects are far above these tolerances (the check is not vacuous)
    p0 = predict_device(scn.device_nominal, {}, t - dt / 2, Tc, res["rate_true_dps"])
    assert np.max(np.abs(p0["drive_frequency_Hz"] - p["drive_frequency_Hz"])) > 1.0
    assert np.max(np.abs(p0["rate_V"] - p["rate_V"])) > 1e-3


def test_forward_block_die_accuracy_below_scoring_floor(tmp_path):
    """The die-temperature floor of the scoring (pipeline.DIE_FLOOR_K) stays well above the model's error.

    Block means (10 s) of the drive frequency, the channel most sensitive to the die, against the
    envelope engine, with no effect and with a thermal lag, in kelvin through |df/dT|."""
    from fmvmg_sim.diagnosis.pipeline import DIE_FLOOR_K
    from fmvmg_sim.scenario import load_scenario
    for name, eff in (("none", {}), ("lag", {"thermal_lag": {"tau_s": 300.0, "offset_K": 0.2}})):
        rec, res = oven_record(tmp_path, name, eff, noise=False)
        scn = load_scenario(tmp_path / f"{name}.toml")
        t = res.time_s
        dt = t[1] - t[0]
        Tc = np.interp(t - dt / 2, t, res["temperature_C"])
        p = predict_device(scn.device_nominal, scn.effects, t - dt / 2, Tc, res["rate_true_dps"])
        B = int(round(10.0 / dt))
        n = (len(t) - 30) // B * B
        err = (res["drive_frequency_Hz"][30:30 + n] - p["drive_frequency_Hz"][30:30 + n]).reshape(-1, B).mean(axis=1)
        slope = np.abs(np.polyfit(Tc, p["drive_frequency_Hz"], 1)[0])
        assert slope > 0.5  # Hz/K: the frequency is a sensitive thermometer (the check is not vacuous)
        assert np.max(np.abs(err)) / slope < DIE_FLOOR_K / 5, (name, np.max(np.abs(err)) / slope)
