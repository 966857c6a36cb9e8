"""Unmodelled effects: validation, their models, and that they act where the physics acts in both engines."""

import numpy as np
import pytest

from fmvmg_sim.averaged import steady_state
from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.diagram import build_diagram
from fmvmg_sim.effects import EFFECT_NAMES, MODELS, EffectSet, first_order_lag, hysteresis_state, validate_effects
from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.errors import InputError
from fmvmg_sim.scenario import load_scenario

CONTRACT_NAMES = ("thermal_lag", "thermal_hysteresis", "temperature_rate", "demod_phase_drift", "quadrature_drift",
                  "q_factor_drift", "mode_split_drift", "feedthrough", "duffing", "flicker_noise", "reference_drift",
                  "stress_relaxation", "quantization")


def test_vocabulary_is_the_contracts():
    assert set(EFFECT_NAMES) == set(CONTRACT_NAMES)
    for name, params in MODELS.items():
        assert 1 <= len(params) <= 3, name
        for p in params.values():
            assert p.lo <= p.prior[0] <= p.prior[1] <= p.hi


@pytest.mark.parametrize("table,where", [
    ({"thermal_lagg": {}}, "effects.thermal_lagg"),
    ({"thermal_lag": {"tau_min": 5}}, "effects.thermal_lag"),
    ({"thermal_lag": {"tau_s": -5}}, "effects.thermal_lag.tau_s"),
    ({"duffing": {"k3_rel": "big"}}, "effects.duffing.k3_rel"),
])
def test_bad_effect_tables_name_the_key(table, where):
    with pytest.raises(InputError) as exc:
        validate_effects(table, "effects")
    assert where in str(exc.value)


def test_first_order_lag_of_a_ramp_lags_by_rate_times_tau():
    t = np.arange(0, 20000.0, 1.0)
    u = 0.01 * t  # 0.6 K/min
    y = first_order_lag(t, u, 600.0)
    assert u[-1] - y[-1] == pytest.approx(0.01 * 600.0, rel=1e-6)
    # uneven steps give the same answer
    t2 = np.sort(np.concatenate([t[::7], t[3::11]]))
    t2 = np.unique(t2)
    y2 = first_order_lag(t2, 0.01 * t2, 600.0)
    assert y2[-1] == pytest.approx(np.interp(t2[-1], t, y), rel=1e-9)


def test_hysteresis_state_depends_on_direction_and_persists():
    T = np.concatenate([np.linspace(25, 60, 351), np.full(100, 60.0), np.linspace(60, 25, 351), np.full(100, 25.0)])
    H = hysteresis_state(T, 5.0)
    assert H[350] == pytest.approx(1.0, abs=1e-3) and H[450] == H[350]       # held through the hold
    assert H[801] == pytest.approx(-1.0, abs=5e-3) and H[-1] == H[801]
    i_up, i_dn = 175, 450 + 176  # both at 42.5 C
    assert abs(T[i_up] - T[i_dn]) < 0.2 and H[i_up] > 0.9 and H[i_dn] < -0.9


def test_effects_fold_into_the_temperature_laws():
    base = load_scenario_named("static_25C")
    fx = EffectSet(validate_effects({"q_factor_drift": {"q_tc_per_K": -0.005}, "mode_split_drift": {"split_Hz_per_K": 0.05},
                                     "demod_phase_drift": {"kappa_urad_per_K": 100.0}}, "effects"))
    dev = fx.apply_to_device(base.device)
    op0, op1 = base.device.at(65.0), dev.at(65.0)
    assert op1["mechanics"]["q_drive"] / op0["mechanics"]["q_drive"] == pytest.approx(np.exp(-0.005 * 40), rel=1e-12)
    assert op1["mechanics"]["f_sense_Hz"] - op0["mechanics"]["f_sense_Hz"] == pytest.approx(2.0, rel=1e-3)
    d0, d1 = build_diagram(base.device, 65.0), build_diagram(dev, 65.0)
    assert d1.phase_trim_rad - d0.phase_trim_rad == pytest.approx(100e-6 * 40, rel=1e-12)


def test_q_drift_keeps_q_positive_over_its_whole_range():
    # the strongest drift the effect allows, 65 K from the reference: Q shrinks by exp(-3.25), a factor 1 + tc dT
    # would have made it negative (and the averaged model unstable)
    base = load_scenario_named("static_25C")
    lo = MODELS["q_factor_drift"]["q_tc_per_K"].lo
    dev = EffectSet(validate_effects({"q_factor_drift": {"q_tc_per_K": lo}}, "effects")).apply_to_device(base.device)
    for T in (-40.0, 85.0):
        q0, q1 = base.device.at(T)["mechanics"], dev.at(T)["mechanics"]
        for m in ("q_drive", "q_sense"):
            assert q1[m] > 0 and q1[m] / q0[m] == pytest.approx(np.exp(lo * (T - 25.0)), rel=1e-12)
    assert steady_state(build_diagram(dev, 85.0)).amplitude_m > 0


def load_scenario_named(name, **kw):
    from .conftest import REPO
    return load_scenario(REPO / "scenarios" / f"{name}.toml", **kw)


EFFECTS_BODY = """
[effects]
feedthrough = { c_ft_fF = 5.0, tc_per_K = 3e-4 }
duffing = { k3_rel = 5e-4 }
demod_phase_drift = { kappa_urad_per_K = 150.0 }
quadrature_drift = { beta_per_K = 2e-3 }
"""


def test_carrier_and_envelope_agree_with_effects_on(make_scenario):
    path = make_scenario(EFFECTS_BODY, duration_s=0.8, temperature_C=60.0, output_rate_Hz=100.0)
    c = run_carrier(load_scenario(path), progress=False)
    e = run_envelope(load_scenario(path, fidelity="envelope"), progress=False)
    scn = load_scenario(path)
    ss = steady_state(build_diagram(scn.device, 60.0))
    sf = c.info["nominal_scale_factor_V_per_dps"]
    for res in (c, e):
        assert np.mean(res["rate_V"][40:]) == pytest.approx(ss.rate_V, abs=3e-3 * abs(ss.quadrature_V))
        assert np.mean(res["quadrature_V"][40:]) == pytest.approx(ss.quadrature_V, rel=3e-3)
        assert np.nanmean(res["drive_frequency_Hz"][40:]) == pytest.approx(ss.f_Hz, abs=0.01)
        assert np.mean(res["agc_effort_V"][40:]) == pytest.approx(ss.agc_effort_V, rel=3e-3)
    # the effects are visible: bias and frequency differ from the nominal device
    nom = steady_state(build_diagram(scn.device_nominal, 60.0))
    assert abs(ss.rate_V - nom.rate_V) / sf > 0.05  # deg/s
    assert ss.f_Hz - nom.f_Hz == pytest.approx(3 / 8 * 5e-4 * nom.f_Hz, rel=0.05)  # Duffing


def test_temperature_rate_effect_adds_g_times_dTdt(make_scenario):
    body = """
[effects]
temperature_rate = { g_dph_per_K_per_min = 360.0 }
"""
    ramp = ['temperature.segments=[{hold_s=60.0},{ramp_to_C=35.0,rate_C_per_min=2.0}]']
    path = make_scenario(body, duration_s=360.0, output_rate_Hz=10.0, fidelity="envelope")
    with_fx = run_envelope(load_scenario(path, fidelity="envelope", overrides=ramp), progress=False)
    path0 = make_scenario("", name="t0", duration_s=360.0, output_rate_Hz=10.0)
    without = run_envelope(load_scenario(path0, fidelity="envelope", overrides=ramp), progress=False)
    t = with_fx.time_s
    ramp = (t > 150) & (t < 340)
    diff = with_fx["rate_dps"][ramp] - without["rate_dps"][ramp]
    assert np.mean(diff) == pytest.approx(360.0 / 3600.0 * 2.0, rel=0.02)  # 0.2 deg/s during the 2 K/min ramp


def test_thermal_lag_moves_the_die_and_the_drive_frequency(make_scenario):
    body = """
[effects]
thermal_lag = { tau_s = 300.0, offset_K = 0.5 }
"""
    ramp = ['temperature.segments=[{hold_s=30.0},{ramp_to_C=45.0,rate_C_per_min=2.0}]']
    path = make_scenario(body, duration_s=630.0, output_rate_Hz=10.0, fidelity="envelope")
    res = run_envelope(load_scenario(path, fidelity="envelope", overrides=ramp), progress=False)
    die, case = res.internal["die_temperature_C"], res["temperature_C"]
    lag = case[-1] - die[-1]
    assert lag == pytest.approx(2.0 / 60 * 300 * (1 - np.exp(-600 / 300)) - 0.5, rel=0.02)
    # the drive frequency follows the die, not the sensor: -0.92 Hz/K
    scn = load_scenario(path, fidelity="envelope", overrides=ramp)
    f_die = steady_state(build_diagram(scn.device, float(die[-1]))).f_Hz
    assert res["drive_frequency_Hz"][-1] == pytest.approx(f_die, abs=0.02)
