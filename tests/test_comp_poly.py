"""poly-baseline, line and bias: recovered thermal laws, model selection, gaps, bursts, missing rows."""

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.utils.validation import check_is_fitted

from fmvmg_sim import api
from fmvmg_sim.compensation import get_method
from fmvmg_sim.compensation.poly import BiasOnly, LineInT, PolyBaseline, check_record
from fmvmg_sim.compensation.synthetic import DriftParams, make_record
from fmvmg_sim.errors import InputError
from fmvmg_sim.record import Record

QUIET = DriftParams(arw_dph_per_rtHz=1.0, bias_instability_dph=0.0, rrw_dph_per_rts=0.0, temp_noise_C=0.0)


def rms(x):
    return float(np.sqrt(np.mean(np.asarray(x) ** 2)))


def test_recovers_thermal_coefficients_and_generalises():
    # a triangle between 25 and 55 C: T and dT/dt vary independently, so all three laws are identifiable
    train = make_record(7200, 10, "ramp", "sines", seed=0, params=QUIET)
    test = make_record(7200, 10, "cooling", "sines", seed=1, params=QUIET)
    comp = get_method("poly-baseline")().fit(train)
    chosen = comp.diagnostics_["selection"]["chosen_settings"]
    assert chosen["order"] >= 2 and chosen["dTdt_smoothing_s"] is not None
    c = {k: v * 3600 for k, v in comp.coef_.items()}  # deg/h units
    dT_ref = comp.T_ref_C_ - 25.0
    assert c["dTdt"] == pytest.approx(25.0, rel=0.05)              # c, deg/h per degC/min
    if chosen["order"] == 2:
        assert c["dT^2"] == pytest.approx(0.02, rel=0.1)          # a2
        assert c["dT"] == pytest.approx(2.0 + 2 * 0.02 * dT_ref, rel=0.05)  # a1 about T_ref
    err = comp.compensate_rate_dps(test) - test["rate_true_dps"]
    raw = test["rate_dps"] - test["rate_true_dps"]
    assert rms(err) < 0.1 * rms(raw)


def test_every_option_is_scored_and_the_best_is_chosen():
    rec = make_record(7200, 10, "ramp", "static", seed=3, params=QUIET)
    sel = PolyBaseline().fit(rec).diagnostics_["selection"]
    names = [r["name"] for r in sel["candidates"]]
    assert len(names) == 4 * 4  # orders 0-3, without dT/dt and with each of three spans
    scores = {r["name"]: r["validation_rms"] for r in sel["candidates"]}
    assert sel["chosen"] == min(scores, key=scores.get)
    assert len(sel["folds"]) == 8  # four forward-chained, four backward-chained
    # a drift with a dT/dt law: every model without dT/dt forecasts worse than the chosen one
    assert all(scores[n] > scores[sel["chosen"]] for n in names if "dT/dt" not in n)


def test_no_thermal_law_selects_a_constant():
    """With no temperature law at all, the selection adds nothing a bias calibration lacks."""
    p = DriftParams(b0_dph=50.0, a1_dph_per_C=0.0, a2_dph_per_C2=0.0, c_dph_per_C_per_min=0.0,
                    scale_ppm_per_C=0.0, bias_instability_dph=0.0, rrw_dph_per_rts=0.0)
    train = make_record(3600, 10, "heating", "static", seed=4, params=p)
    test = make_record(3600, 10, "cooling", "static", seed=5, params=p)
    poly = PolyBaseline().fit(train)
    bias = BiasOnly().fit(train)
    assert rms(poly.compensate_rate_dps(test)) <= 1.01 * rms(bias.compensate_rate_dps(test))


def test_tangent_beyond_the_training_range():
    """A quadratic fitted on 25-35 C is continued along its tangent at 35 C, and the report says so."""
    t = np.arange(0, 3600.0, 0.1)
    T = 25 + 10 * t / t[-1]
    rate = 0.01 * (T - 25) ** 2 / 10 + np.random.default_rng(0).normal(0, 1e-4, t.size)
    train = Record({"time_s": t, "temperature_C": T, "rate_dps": rate})
    m = PolyBaseline(orders=(2,), dtdt_smoothing_s=(None,), continuation="tangent").fit(train)
    T2 = np.full(t.size, 45.0)
    test = Record({"time_s": t, "temperature_C": T2, "rate_dps": np.zeros(t.size)})
    drift = -m.compensate_rate_dps(test)
    # value and slope of 0.001 (T-25)^2 at 35 C: 0.1 and 0.02 per K -> 0.3 at 45 C (the parabola gives 0.4)
    assert drift.mean() == pytest.approx(0.1 + 0.02 * 10, rel=0.01)
    ex = m.transform_diagnostics_["extrapolation"]
    assert ex["any"] and ex["variables"]["temperature_C"]["above"] == pytest.approx(10.0, abs=0.01)
    assert ex["terms_continued_linearly"] == ["dT^2"] and "10 degC above" in ex["summary"]


def test_line_and_bias_are_fixed_baselines():
    rec = make_record(3600, 10, "ramp", "static", seed=6)
    line, bias = LineInT().fit(rec), BiasOnly().fit(rec)
    assert line.model_.model_.terms == ["1", "dT"] and bias.model_.model_.terms == ["1"]
    T = rec["temperature_C"]
    slope = np.polyfit(T, rec["rate_dps"], 1)[0]
    assert line.coef_["dT"] == pytest.approx(slope, rel=0.02)  # 1 s bin means vs samples: same line
    assert bias.coef_["1"] == pytest.approx(np.mean(rec["rate_dps"] - rec["rate_true_dps"]), abs=1e-6)


def test_handles_gaps_and_refuses_them_where_needed():
    rec = make_record(3600, 10, "heating", "static", seed=2)
    keep = np.ones(len(rec), bool)
    keep[10000:13000] = False  # a 300 s gap
    gappy = rec.slice(keep)
    comp = get_method("poly-baseline")()
    assert comp.handles_gaps
    out = comp.fit(gappy).compensate_rate_dps(gappy)
    assert out.shape == (len(gappy),) and np.all(np.isfinite(out))
    with pytest.raises(InputError, match="uneven steps"):
        check_record(gappy, need_uniform=True, method="emd-rbf")


def test_bursts_offer_no_derivative_and_folds_cut_between_bursts():
    rec = make_record(6000, 10, "cooling", "static", seed=7)
    t = rec.time_s
    bursty = rec.slice((t % 300.0) < 5.0)  # 5 s every 300 s, like a thermal-vacuum log
    m = PolyBaseline().fit(bursty)
    d = m.diagnostics_
    assert d["sampling"]["bursty"] and d["sampling"]["segments"] == 20
    assert all(r["settings"]["dTdt_smoothing_s"] is None for r in d["selection"]["candidates"])
    assert any("not offered" in n for n in d["notes"])
    starts = bursty.time_s[np.r_[0, np.flatnonzero(np.diff(bursty.time_s) > 1) + 1]]
    for f in d["selection"]["folds"]:  # every scored block starts at a burst (bin means are <= 0.5 s in)
        assert np.min(np.abs(starts - f["scored_from_s"])) < 1.0
    with pytest.raises(InputError, match="bursts of about 5 s every 300 s"):
        check_record(bursty, need_uniform=True, method="vmd-wflp-cssvr")


def test_missing_rows_become_gaps():
    rec = make_record(1800, 10, "heating", "static", seed=8)
    rec.columns["temperature_C"] = rec["temperature_C"].copy()
    rec.columns["temperature_C"][5] = np.nan
    m = get_method("poly-baseline")().fit(rec)
    out = m.compensate_rate_dps(rec)
    assert np.isnan(out[5]) and np.isfinite(np.delete(out, 5)).all()
    assert any("data row 6" in n for n in m.diagnostics_["notes"])
    with pytest.raises(InputError, match="temperature_C has 1 missing"):
        check_record(rec, need_uniform=True, method="emd-rbf")


@pytest.mark.parametrize("name", api.compensators())
def test_unfitted_compensator_raises_not_fitted(name):
    """Every registered method: clone round-trips, and before fit scikit-learn's NotFittedError, not AttributeError."""
    comp = get_method(name)()
    assert clone(comp).get_params() == comp.get_params()
    rec = make_record(600, 10, "heating", "static", seed=9)
    with pytest.raises(NotFittedError):
        check_is_fitted(comp)
    for call in (comp.transform, comp.compensate_rate_dps):
        with pytest.raises(NotFittedError):
            call(rec)
    with pytest.raises(NotFittedError):
        comp.selection_report()


@pytest.mark.parametrize("name", ["poly-baseline", "line", "bias", "physics"])
def test_transform_returns_the_compensated_record(name):
    """transform gives a record: rate_dps compensated, the input's in rate_raw_dps, every other channel copied."""
    rec = make_record(600, 10, "heating", "static", seed=9)
    rec.metadata["device"] = "fmvmg-a"
    comp = get_method(name)().fit(rec)
    check_is_fitted(comp)
    out = comp.transform(rec)
    assert isinstance(out, Record) and len(out) == len(rec)
    np.testing.assert_array_equal(out["rate_dps"], comp.compensate_rate_dps(rec))
    np.testing.assert_array_equal(out["rate_raw_dps"], rec["rate_dps"])
    for c in rec.columns:
        if c != "rate_dps":
            np.testing.assert_array_equal(out[c], rec[c])
    assert out.metadata == {**rec.metadata, "compensation_method": name}
    assert "rate_raw_dps" not in rec  # the input is left alone
    assert np.std(out["rate_dps"]) < np.std(rec["rate_dps"]) or name == "bias"
    np.testing.assert_allclose(get_method(name)().fit_transform(rec)["rate_dps"], out["rate_dps"])
