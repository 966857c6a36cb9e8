"""Evaluations and held-out scoring: the physical-bound rule, parameter significance, the fold rule, and the
prediction's own uncertainty in the held-out likelihood (the fits themselves are tested on records)."""

from types import SimpleNamespace

import numpy as np
import pytest

from fmvmg_sim.diagnosis.attribution import DETERMINISTIC, TEMPERATURE_DRIVEN, separating_experiment
from fmvmg_sim.diagnosis.evaluation import BOUND_REASON, PIN_CHI2, bound_check, bounds_verdict, param_z
from fmvmg_sim.diagnosis.fitting import Fitter, Lin
from fmvmg_sim.diagnosis.forward import CHANNELS, predict_device
from fmvmg_sim.diagnosis.heldout import (FOLD_JOIN_NATS, FOLDS_COMBINED_Z, FoldScore, HeldOutGain, Scorer)
from fmvmg_sim.diagnosis.model import ModelFit
from fmvmg_sim.effects import validate_effects
from fmvmg_sim.scenario import load_scenario
from tests.test_diagnosis_helpers import REPO


def test_pinned_and_zero_bounds():
    assert bound_check({"feedthrough": {"c_ft_fF": 0.0, "tc_per_K": 0.0}}) == (None, [])   # zero: "no effect"
    # near a non-zero bound: judged by whether the data pull it past (bounds_verdict)
    assert bound_check({"feedthrough": {"c_ft_fF": 1.0, "tc_per_K": -0.01}}) == (None, ["feedthrough.tc_per_K"])
    assert bound_check({"feedthrough": {"c_ft_fF": 1.0, "tc_per_K": 0.02}}) == (BOUND_REASON, [])     # outside


def test_relaxation_has_a_floor_of_an_hour_instead_of_a_pin_at_its_lower_bound():
    # relaxation takes hours (physics brief section 4), warm-up minutes: an attribution floor says so
    sr = lambda tau: {"stress_relaxation": {"quad_rel": 0.002, "tau_h": tau}}   # noqa: E731
    assert bound_check(sr(1.005)) == (None, [])
    assert bound_check(sr(0.9))[0] == "a relaxation faster than an hour (warm-up-like)"
    assert bound_check(sr(999.5)) == (BOUND_REASON, [])        # at the upper bound
    assert bound_check(sr(1500.0)) == (BOUND_REASON, [])       # outside (the refinement can overshoot)
    # other time constants and widths keep the pin at their lower bound
    assert bound_check({"thermal_lag": {"tau_s": 13.3, "offset_K": 0.5}}) == (BOUND_REASON, [])
    assert bound_check({"thermal_hysteresis": {"quad_rel": 0.01, "width_K": 0.55}}) == (BOUND_REASON, [])
    assert bound_check({"thermal_hysteresis": {"quad_rel": 0.01, "width_K": 5.0}}) == (None, [])


def _bounded_fit(g_true):
    """A temperature-rate term fitted beside an offset knob on synthetic blocks (bounds +-2000; its standard
    error 0.7)."""
    n = 400
    x = 1e-2 * np.sin(np.linspace(0.0, 6.0, n))[:, None]        # the term's column (per deg/h per K/min)
    f = Fitter.__new__(Fitter)
    f.Y = 0.3 + g_true * x + 0.1 * np.random.default_rng(0).standard_normal((n, 1))
    f.S, f.present = np.full((n, 1), 0.1), np.ones(1, bool)
    name = "temperature_rate.g_dph_per_K_per_min"
    lin = Lin(np.zeros((n, 1)), np.stack([np.ones((n, 1)), x], axis=-1), ["offset", name], np.zeros(2),
              np.array([np.nan, np.nan]), np.array([-10.0, -2000.0]), np.array([10.0, 2000.0]))
    sol = f.solve(lin, np.ones(n, bool))
    mf = ModelFit({"temperature_rate": {"g_dph_per_K_per_min": float(sol.x[1])}}, {}, sol, lin)
    return mf, SimpleNamespace(f=f, train=np.ones(n, bool))


def test_a_parameter_near_its_bound_is_pinned_only_when_the_data_pull_it_past():
    # an optimum 2 units inside the bound (within the 4-unit tolerance, 3 standard errors in): kept
    mf, sc = _bounded_fit(1998.0)
    g = mf.effects["temperature_rate"]["g_dph_per_K_per_min"]
    assert 1996.0 < g < 2000.0 and bound_check(mf.effects) == (None, ["temperature_rate.g_dph_per_K_per_min"])
    assert bounds_verdict(sc, mf) == (True, None)
    # the data pull it 140 standard errors past: held at the bound and pinned
    mf, sc = _bounded_fit(2100.0)
    assert mf.effects["temperature_rate"]["g_dph_per_K_per_min"] == pytest.approx(2000.0)
    assert bounds_verdict(sc, mf) == (False, BOUND_REASON)
    # judged on the blocks the fit was made on: an interior optimum on all blocks stays kept when the scorer's
    # training window is shorter
    mf, sc = _bounded_fit(1998.0)
    all_rows = sc.train.copy()
    sc.train = np.arange(len(all_rows)) < len(all_rows) // 3
    assert bounds_verdict(sc, mf, all_rows) == (True, None)


def test_a_relaxation_below_its_floor_is_refused_only_when_the_data_pull_it_there():
    # a relaxation fitted just under an hour whose cost barely rises at the floor is not warm-up; one fitted at
    # 0.013 h whose cost rises by 400 at the floor is refused
    def fit(tau, strain):
        mf = ModelFit({"stress_relaxation": {"quad_rel": 2e-4, "tau_h": tau}}, {}, SimpleNamespace(cost=100.0), None)
        mf._ctx["cost_at"] = lambda over, rows: 100.0 + (strain if over == {"stress_relaxation": 1.0} else np.nan)
        return mf

    scorer = SimpleNamespace(train=np.ones(4, bool))
    assert bounds_verdict(scorer, fit(0.98, 0.5 * PIN_CHI2)) == (True, None)
    assert bounds_verdict(scorer, fit(0.013, 400.0)) == (False, "a relaxation faster than an hour (warm-up-like)")
    mf = fit(0.98, 0.0)
    del mf._ctx["cost_at"]  # a fit that cannot re-solve keeps the floor as it was
    assert bounds_verdict(scorer, mf)[0] is False


def test_parameter_z_is_value_over_noise_model_sd():
    """The largest |value| / sd over the named effects' parameters; undefined errors are skipped; a thermal
    lag is judged by its held-out gain (its time constant), so its z is infinite."""
    mf = SimpleNamespace(
        effects={"quadrature_drift": {"beta_per_K": 3e-4},
                 "reference_drift": {"vref_tc_per_K": -2e-6, "rectifier_mV_per_K": 0.5},
                 "thermal_lag": {"tau_s": 600.0, "offset_K": 0.0}},
        sd_noise={"quadrature_drift": {"beta_per_K": 2e-4},
                  "reference_drift": {"vref_tc_per_K": 1e-6, "rectifier_mV_per_K": np.nan},
                  "thermal_lag": {"offset_K": 1.0}})
    assert np.isclose(param_z(mf, ["quadrature_drift"]), 1.5)
    assert np.isclose(param_z(mf, ["reference_drift"]), 2.0)
    assert np.isclose(param_z(mf, ["quadrature_drift", "reference_drift"]), 2.0)
    assert param_z(mf, ["thermal_lag"]) == np.inf


def test_separating_experiment_is_symmetric():
    a = separating_experiment("reference_drift", "q_factor_drift")
    assert a == separating_experiment("q_factor_drift", "reference_drift")
    assert "set-point" in a


def _gain(*folds):
    return HeldOutGain(0.0, [0.0, 0.0], list(folds))


def _scorer(folds_needed=2):
    sc = Scorer.__new__(Scorer)
    sc.folds_needed = folds_needed
    return sc


def fold(total, info, passed=None, consistent=True):
    """A fold score: ``passed`` sets its interval above zero (its total decides the rest)."""
    ci = [0.1, 1.0] if (passed if passed is not None else total >= 3.0) else [-0.1, 1.0]
    return FoldScore(total / 100.0, ci, total, info, consistent)


def test_fold_rule_two_folds_or_the_only_testable_one():
    sc = _scorer()
    assert sc.folds_ok(_gain(fold(5.0, 12.0), fold(5.0, 1.0), fold(-1.0, 12.0)))
    assert not sc.folds_ok(_gain(fold(5.0, 12.0), fold(-1.0, 12.0), fold(-1.0, 1.0)))
    # a ramp-rate term tested on the one fold with a ramp: it must pass and earn what it would if true
    assert sc.folds_ok(_gain(fold(5.0, 12.0), fold(-1.0, 1.0), fold(-1.0, 1.0)))
    assert not sc.folds_ok(_gain(fold(5.0, 12.0, consistent=False), fold(-1.0, 1.0), fold(-1.0, 1.0)))
    assert not sc.folds_ok(_gain(fold(5.0, 1.0), fold(-1.0, 1.0), fold(-1.0, 1.0)))  # nothing can test it


def test_fold_rule_testable_folds_together():
    """A near-limit effect: two folds can test it, one passes; together they carry it (or contradict it)."""
    sc = _scorer()
    # 9 + 25 nats where 11 + 16 were expected: 34 >= 2 sqrt(2 * 27) = 14.7
    assert FOLDS_COMBINED_Z * (2 * 27.0) ** 0.5 < 34.0
    assert sc.folds_ok(_gain(fold(9.2, 11.0, passed=False), fold(-3.0, 4.0), fold(25.3, 16.0)))
    assert not sc.folds_ok(_gain(fold(-2.0, 11.0), fold(1.0, 4.0), fold(40.0, 30.0)))          # one loses
    assert not sc.folds_ok(_gain(fold(5.0, 11.0, passed=False), fold(60.0, 16.0, consistent=False)))
    assert not sc.folds_ok(_gain(fold(3.5, 40.0, passed=False), fold(4.0, 40.0, passed=False)))  # within scatter


def test_fold_rule_folds_that_carry_it_join_the_combined_test():
    """The one fold that can test a near-limit term alone gains 8.0 of 12.5 nats expected (not a pass); a fold
    expecting 9.0 gains 12.5. Together they stand 3.1 scatters above zero; folds below FOLD_JOIN_NATS stay out."""
    sc = _scorer()
    assert FOLD_JOIN_NATS < 8.96 < 10.0
    assert sc.folds_ok(_gain(fold(12.48, 8.96), fold(8.0, 12.47, passed=False), fold(0.65, 2.1)))
    assert not sc.folds_ok(_gain(fold(12.48, 4.0), fold(8.0, 12.47, passed=False), fold(0.65, 2.1)))


def _stub(Y, folds):
    """A :class:`Scorer` on given blocks: unit block sigma, white unit-variance noise model, no fitter behind it."""
    S = np.ones_like(Y)
    f = SimpleNamespace(Y=Y, S=S, S_score=S, S_loc=S, present=np.ones(Y.shape[1], bool), converter={})
    f.residual = lambda pred, scoring=False, Y=None: Fitter.residual(f, pred, scoring, Y)
    f.law_sd = lambda train: np.zeros_like(S)
    sc = Scorer.__new__(Scorer)
    sc.f, sc.folds, sc.noise_params, sc.folds_needed = f, folds, [(0.0, 1.0)] * Y.shape[1], 2
    return sc


def test_a_prediction_its_training_window_does_not_determine_is_scored_as_uncertain():
    """Three folds; the candidate is right everywhere but, on the first fold, 30 sigma off where its refit leaves
    the prediction uncertain by 50 sigma (a scale factor with no applied rate to learn it from, a knob its parameter
    makes collinear on a short window). Scored with its predictive uncertainty the first fold counts for little
    and the two others decide; scored as one exact point it would sink the pooled interval."""
    n = 120
    folds = [{"train": np.arange(n) < 30 + 30 * k, "test": (np.arange(n) >= 30 + 30 * k) & (np.arange(n) < 60 + 30 * k)}
             for k in range(3)]
    truth = np.where(np.arange(n) >= 30, 3.0, 0.0)[:, None]       # an effect: 3 sigma on every held-out block
    Y = truth + np.random.default_rng(2).standard_normal((n, 1))
    sc = _stub(Y, folds)
    lin = Lin(np.zeros((n, 1)), np.ones((n, 1, 1)), ["k"], np.zeros(1), np.array([np.nan]), np.array([-1e3]),
              np.array([1e3]))
    base = sc.fold_predictions(lambda rows: (np.zeros((n, 1)), {}, (lin, np.array([[0.0]]))))
    calls = iter(range(3))

    def refit(rows):
        wild = next(calls) == 0
        return truth + (30.0 if wild else 0.0), {}, (lin, np.array([[50.0 ** 2 if wild else 0.0]]))
    cand = sc.fold_predictions(refit)
    assert cand["folds"][0][2][0, 0] == pytest.approx(50.0)
    g = sc.gain(cand, base)
    assert abs(g.folds[0].total) < 0.5 * abs(g.folds[1].total) and g.folds_passed >= 2 and g.ci[0] > 2.0
    exact = {"folds": [(p, e, np.zeros_like(sd)) for p, e, sd in cand["folds"]], "heldout": cand["heldout"]}
    assert sc.gain(exact, base).ci[0] < 0


def test_temperature_driven_effects_are_constant_on_a_hold():
    """On the forward model each effect of TEMPERATURE_DRIVEN, at the middle of its prior range, leaves a record
    held at one temperature unchanged in time (a constant offset at most), while a ramp moves it; a stress
    relaxation moves a hold too (it acts through time), so it is left out."""
    dev = load_scenario(REPO / "scenarios" / "nominal_a.toml").device_nominal
    t = np.arange(0.0, 20000.0, 200.0)
    hold, ramp = np.full_like(t, 25.0), 25.0 + 40.0 * t / t[-1]

    def moves(eff, T):  # peak-to-peak over time of the signature, per channel
        a, b = predict_device(dev, eff, t, T), predict_device(dev, {}, t, T)
        return np.ptp(np.stack([a[c] - b[c] for c in CHANNELS], axis=1), axis=0)
    assert set(TEMPERATURE_DRIVEN) == set(DETERMINISTIC) - {"stress_relaxation"}
    for n in DETERMINISTIC:
        eff = validate_effects({n: {}}, n)
        on_hold, on_ramp = moves(eff, hold), moves(eff, ramp)
        assert on_ramp.max() > 0, n
        if n in TEMPERATURE_DRIVEN:
            assert np.all(on_hold <= 1e-9 * np.maximum(on_ramp, 1e-300)), (n, on_hold, on_ramp)
        else:
            assert np.max(on_hold / np.maximum(on_ramp, 1e-300)) > 0.1, (n, on_hold, on_ramp)
