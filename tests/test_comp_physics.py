"""The ``physics`` compensator: auxiliary-channel drift model, fallback, held-out behaviour."""

import numpy as np
import pytest

from fmvmg_sim.compensation import get_method
from fmvmg_sim.compensation.physics import PhysicsCompensator, PhysicsFallbackWarning, find_device
from fmvmg_sim.compensation.poly import PolyBaseline
from fmvmg_sim.compensation.synthetic import make_record
from fmvmg_sim.errors import InputError
from fmvmg_sim.record import Record
from fmvmg_sim.validation.compensation_eval import RunCache, _oven_profiles, default_effects


def drift_rms_dph(rec, out, block_s=100.0):
    err = np.asarray(out) - rec["rate_true_dps"]
    m = int(round(block_s / rec.sample_interval_s()))
    n = len(err) // m * m
    return float(np.sqrt(np.mean(err[:n].reshape(-1, m).mean(1) ** 2)) * 3600.0)


@pytest.fixture(scope="module")
def runs():
    """Quick simulated oven runs (20 Hz, 30 min) with a 120 s case-to-die thermal lag."""
    cache = RunCache(_oven_profiles(quick=True), default_effects(quick=True))
    return cache.get("oven_000", 101), cache.get("oven_004", 201)


def test_registered():
    assert get_method("physics") is PhysicsCompensator


def test_beats_poly_baseline_held_out_with_thermal_lag(runs):
    """With the die lagging the case, the die temperature read from the drive frequency explains what the case
    temperature cannot: held out, physics is never worse than the polynomial in temperature, and where its
    forward-chained validation keeps the auxiliary-channel model (it may keep a temperature model instead, which
    then matches the polynomial) it at least halves the drift."""
    a, b = runs
    kept = 0
    for train, test in ((a, b), (b, a)):
        raw = drift_rms_dph(test, test["rate_dps"])
        poly = drift_rms_dph(test, PolyBaseline().fit(train).compensate_rate_dps(test))
        phys_model = PhysicsCompensator().fit(train)
        phys = drift_rms_dph(test, phys_model.compensate_rate_dps(test))
        assert poly < raw
        assert phys <= 1.02 * poly, (raw, poly, phys)
        d = phys_model.diagnostics_
        assert not d["fallback_temperature_only"] and d["die_temperature_source"] == "drive_frequency_Hz"
        names = [r["name"] for r in d["selection"]["candidates"]]
        assert any(n.startswith("temperature:") for n in names) and any("Q*dT_die" in n for n in names)
        # the drive-frequency slope is config A's, from its device file: f0 * tcf = 30740 Hz * -30 ppm/K
        assert d["drive_frequency_tc_Hz_per_K"] == pytest.approx(30740.0 * -30e-6, rel=1e-3)
        assert "fmvmg-a" in d["drive_frequency_tc_source"]
        if d["model_family"] != "auxiliary channels":
            continue
        kept += 1
        assert phys < 0.5 * poly, (raw, poly, phys)
        assert "dT_die" in d["terms"]
        # the electronics sit on the case: a case-temperature term is chosen beside the die's
        assert any(term.startswith("dT_case") for term in d["terms"]), d["terms"]
        assert d["filter_time_constant_s"] == 0.0
    assert kept >= 1


def test_signal_path_untouched(runs):
    """The output is the input minus a slow correction: no bandwidth is filtered away."""
    a, b = runs
    m = PhysicsCompensator().fit(a)
    corr = b["rate_dps"] - m.compensate_rate_dps(b)
    assert np.std(np.diff(corr)) < 1e-3 * np.std(np.diff(b["rate_dps"]))
    np.testing.assert_allclose(corr, m.drift(b))


def test_drive_frequency_slope_from_the_device_file():
    """The slope is the device's own number: f_drive x its linear TCF (the quadratic term cancels at the reference).

    Config B's drive resonance (9.6 kHz) moves 3.2 times less per kelvin than config A's (30.7 kHz).
    """
    a, b = find_device("fmvmg-a"), find_device("fmvmg_b")
    for dev in (a, b):
        v = dev.values
        assert dev.drive_frequency_tc_Hz_per_K == pytest.approx(
            v["mechanics"]["f_drive_Hz"] * v["thermal"]["tcf_linear_per_K"], rel=1e-6)
    assert a.drive_frequency_tc_Hz_per_K / b.drive_frequency_tc_Hz_per_K == pytest.approx(30740.0 / 9609.6, rel=1e-3)
    assert find_device("no-such-device") is None


def test_agc_auto_drops_collinear_term(runs):
    m = PhysicsCompensator(use_agc="auto").fit(runs[0])
    # in the default device the damping is a function of temperature alone
    assert m.diagnostics_["agc_r2_on_die_temperature"] > 0.999
    assert not any("A_agc" in r["name"] for r in m.diagnostics_["selection"]["candidates"])
    forced = PhysicsCompensator(use_agc=True).fit(runs[0])
    assert any("A_agc" in r["name"] for r in forced.diagnostics_["selection"]["candidates"])
    with pytest.raises(ValueError):
        PhysicsCompensator(use_agc="maybe").fit(runs[0])


def test_fallback_without_auxiliary_channels():
    train = make_record(duration_s=3600, fs_Hz=10.0, profile="heating", seed=1)
    test = make_record(duration_s=3600, fs_Hz=10.0, profile="heating", seed=2)
    with pytest.warns(PhysicsFallbackWarning, match="temperature-only"):
        m = PhysicsCompensator().fit(train)
    assert m.diagnostics_["fallback_temperature_only"] is True
    poly = PolyBaseline().fit(train)
    assert m.diagnostics_["terms"] == poly.diagnostics_["terms"]  # the same selected temperature model
    assert m.diagnostics_["selection"]["chosen"] == poly.diagnostics_["selection"]["chosen"]
    out = m.compensate_rate_dps(test)
    np.testing.assert_allclose(out, poly.compensate_rate_dps(test))
    assert drift_rms_dph(test, out) < 0.5 * drift_rms_dph(test, test["rate_dps"])


def test_partial_channels_warn_and_drop_terms(runs):
    a, b = runs
    cols = {k: v for k, v in a.columns.items() if k != "drive_frequency_Hz"}
    with pytest.warns(PhysicsFallbackWarning, match="drive_frequency_Hz"):
        m = PhysicsCompensator().fit(Record(cols))
    assert m.diagnostics_["die_temperature_source"] == "temperature_C"
    assert m.diagnostics_["fallback_temperature_only"] is False
    assert m.compensate_rate_dps(b).shape == (len(b),)


def test_transform_needs_the_fitted_channels(runs):
    a, b = runs
    m = PhysicsCompensator().fit(a)
    cols = {k: v for k, v in b.columns.items() if k != "quadrature_V"}
    with pytest.raises(InputError, match="quadrature_V"):
        m.compensate_rate_dps(Record(cols))


def test_handles_gaps(runs):
    a, b = runs
    keep = np.ones(len(b), bool)
    keep[5000:7000] = False
    m = PhysicsCompensator().fit(a.slice(keep))
    out = m.compensate_rate_dps(b.slice(keep))
    assert out.shape == (keep.sum(),) and np.isfinite(out).all()


def test_bad_input():
    rec = make_record(duration_s=60, fs_Hz=10.0, seed=0)
    cols = {k: v for k, v in rec.columns.items() if k != "temperature_C"}
    with pytest.raises(InputError, match="temperature_C"):
        PhysicsCompensator().fit(Record(cols))
