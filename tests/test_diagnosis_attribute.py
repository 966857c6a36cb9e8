"""Attribution bookkeeping: ambiguity sets and the physical-bound rule (the fits are tested end to end)."""

import contextlib

import numpy as np
import pytest

from fmvmg_sim.diagnosis.attribute import (BOUND_REASON, FOLDS_REASON, _significant_param, ambiguity, bound_check,
                                           bounds_verdict, located_gap_candidate, param_z, separating_experiment)
from tests.test_diagnosis_helpers import REPO


def _ev(gain, lo, inb=True, fit=True):
    return {"fit": object() if fit else None, "in_bounds": inb, "gain": {"gain": gain, "ci": [lo, gain + 1.0]}}


def test_ambiguity_set_is_the_best_ones_interval():
    evals = {"q_factor_drift": _ev(10.0, 6.0), "reference_drift": _ev(9.5, 5.0),   # inside: look-alike
             "demod_phase_drift": _ev(2.0, 1.0),                                   # below the interval
             "feedthrough": _ev(9.0, 4.0, inb=False),                              # pinned at a bound
             "duffing": _ev(7.0, -0.5),                                            # interval reaches zero
             "thermal_lag": _ev(8.0, 3.0, fit=False)}                              # no fit
    assert ambiguity(evals, "q_factor_drift") == ["reference_drift"]
    assert ambiguity(evals, "reference_drift") == ["q_factor_drift"]


def test_a_located_gap_is_named_by_an_effect_that_fails_only_the_fold_count():
    def ev(gain, why, fit=True):
        return {"gain": {"gain": gain, "ci": [0.1, 2 * gain]}, "fit": object() if fit else None, "why_not": why}
    single = {"feedthrough": ev(1.97, [FOLDS_REASON]), "temperature_rate": ev(0.22, [FOLDS_REASON]),
              "thermal_hysteresis": ev(5.0, ["held-out gain interval reaches zero", FOLDS_REASON]),
              "mode_split_drift": ev(9.0, [FOLDS_REASON, "dBIC not below -10"]),
              "duffing": ev(50.0, [FOLDS_REASON], fit=False)}
    assert located_gap_candidate(single) == "feedthrough"        # the largest gain of those failing only that
    del single["feedthrough"], single["temperature_rate"]
    assert located_gap_candidate(single) is None                 # every other one fails more


def test_pinned_and_zero_bounds():
    assert bound_check({"feedthrough": {"c_ft_fF": 0.0, "tc_per_K": 0.0}}) == (None, [])   # zero: "no effect"
    # near a non-zero bound: judged by whether the data pull it past (bounds_verdict)
    assert bound_check({"feedthrough": {"c_ft_fF": 1.0, "tc_per_K": -0.01}}) == (None, ["feedthrough.tc_per_K"])
    assert bound_check({"feedthrough": {"c_ft_fF": 1.0, "tc_per_K": 0.02}}) == (BOUND_REASON, [])     # outside


def test_relaxation_has_a_floor_of_an_hour_instead_of_a_pin_at_its_lower_bound():
    # 0.01-1000 h: a thousandth of the range (1 h) put everything under 1.01 h "at" the 0.01 h bound; the
    # attribution floor says what is meant (relaxation takes hours, warm-up minutes)
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
    from fmvmg_sim.diagnosis.fitting import Fitter, Lin
    from fmvmg_sim.diagnosis.model import ModelFit

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
    scorer = type("S", (), {"f": f, "train": np.ones(n, bool)})()
    return mf, scorer


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
    # judged on the blocks the fit was made on (the in-sample hint fits the whole record, not the training
    # window): an interior optimum on all blocks stays kept when the scorer's training window is shorter
    mf, sc = _bounded_fit(1998.0)
    all_rows = sc.train.copy()
    sc.train = np.arange(len(all_rows)) < len(all_rows) // 3
    assert bounds_verdict(sc, mf, all_rows) == (True, None)


def test_why_not_names_each_failed_criterion():
    from fmvmg_sim.diagnosis.attribute import why_not

    good = {"gain": {"ci": [0.5, 2.0]}, "delta_bic": -40.0, "in_bounds": True, "param_significant": True}
    assert why_not(good, folds_ok=True) == []
    assert why_not(good, folds_ok=False) == ["too few held-out folds pass"]
    bad = {"gain": {"ci": [-0.1, 2.0]}, "delta_bic": -5.0, "in_bounds": False, "param_significant": False}
    assert len(why_not(bad, folds_ok=True)) == 4
    assert why_not(dict(good, delta_bic=-5.0), True) == ["dBIC not below -10"]


def test_parameter_z_is_value_over_noise_model_sd():
    """The largest |value| / sd over the named effects' parameters; undefined errors are skipped; a thermal
    lag is judged by its held-out gain (its time constant), so its z is infinite."""
    class _MF:
        effects = {"quadrature_drift": {"beta_per_K": 3e-4}, "reference_drift": {"vref_tc_per_K": -2e-6,
                                                                                  "rectifier_mV_per_K": 0.5},
                   "thermal_lag": {"tau_s": 600.0, "offset_K": 0.0}}
        sd_noise = {"quadrature_drift": {"beta_per_K": 2e-4}, "reference_drift": {"vref_tc_per_K": 1e-6,
                                                                                   "rectifier_mV_per_K": np.nan},
                    "thermal_lag": {"offset_K": 1.0}}
    mf = _MF()
    assert np.isclose(param_z(mf, ["quadrature_drift"]), 1.5)
    assert np.isclose(param_z(mf, ["reference_drift"]), 2.0)
    assert np.isclose(param_z(mf, ["quadrature_drift", "reference_drift"]), 2.0)
    assert param_z(mf, ["thermal_lag"]) == np.inf
    assert not _significant_param(mf, ["quadrature_drift"]) and not _significant_param(mf, ["reference_drift"])
    mf.effects["reference_drift"]["vref_tc_per_K"] = -2.1e-6
    assert _significant_param(mf, ["reference_drift"]) and _significant_param(mf, ["thermal_lag"])


def test_separating_experiment_is_symmetric():
    a = separating_experiment("reference_drift", "q_factor_drift")
    assert a == separating_experiment("q_factor_drift", "reference_drift")
    assert "set-point" in a


def test_fold_rule_two_folds_or_the_only_testable_one():
    from fmvmg_sim.diagnosis.attribute import Scorer

    sc = Scorer.__new__(Scorer)
    sc.folds_needed = 2

    def fold(testable, passed, consistent=True):
        return {"testable": testable, "passed": passed, "consistent": consistent,
                "total": 5.0 if passed else -1.0, "info_if_true": 12.0 if testable else 1.0}

    def g(*folds):
        return {"folds": list(folds), "folds_passed": sum(f["passed"] for f in folds)}
    assert sc.folds_ok(g(fold(True, True), fold(False, True), fold(True, False)))
    assert not sc.folds_ok(g(fold(True, True), fold(True, False), fold(False, False)))
    # a ramp-rate term tested on the one fold with a ramp: it must pass and earn what it would if true
    assert sc.folds_ok(g(fold(True, True), fold(False, False), fold(False, False)))
    assert not sc.folds_ok(g(fold(True, True, consistent=False), fold(False, False), fold(False, False)))
    assert not sc.folds_ok(g(fold(False, True), fold(False, False), fold(False, False)))  # nothing can test it


def test_fold_rule_testable_folds_together():
    """A near-limit effect: two folds can test it, one passes; together they carry it (or contradict it)."""
    from fmvmg_sim.diagnosis.attribute import FOLDS_COMBINED_Z, Scorer

    sc = Scorer.__new__(Scorer)
    sc.folds_needed = 2

    def fold(total, info, passed=False, consistent=True):
        return {"testable": info >= 10.0, "passed": passed, "consistent": consistent, "total": total,
                "info_if_true": info}

    def g(*folds):
        return {"folds": list(folds), "folds_passed": sum(f["passed"] for f in folds)}
    # 9 + 25 nats where 11 + 16 were expected: 34 >= 2 sqrt(2 * 27) = 14.7
    assert FOLDS_COMBINED_Z * (2 * 27.0) ** 0.5 < 34.0
    assert sc.folds_ok(g(fold(9.2, 11.0), fold(-3.0, 4.0), fold(25.3, 16.0, passed=True)))
    # one testable fold loses: they contradict each other
    assert not sc.folds_ok(g(fold(-2.0, 11.0), fold(1.0, 4.0), fold(40.0, 30.0, passed=True)))
    # a fold gaining far more than the candidate could: it leans on another misfit
    assert not sc.folds_ok(g(fold(5.0, 11.0), fold(60.0, 16.0, passed=True, consistent=False)))
    # both gain, but the sum is within the scatter of a false candidate's
    assert not sc.folds_ok(g(fold(3.5, 40.0), fold(4.0, 40.0)))


def test_fold_rule_folds_that_carry_it_join_the_combined_test():
    """A near-limit ramp-rate term (development case 90070/1): the one fold that can test it alone gains 8.0 of
    the 12.5 nats expected, not enough to pass; a fold expecting 9.0 gains 12.5. Together they stand 3.1 scatters
    above zero, so the candidate is carried; folds below FOLD_JOIN_NATS stay out of the sum."""
    from fmvmg_sim.diagnosis.attribute import FOLD_JOIN_NATS, FOLDS_COMBINED_Z, Scorer

    sc = Scorer.__new__(Scorer)
    sc.folds_needed = 2

    def fold(total, info, passed=False, consistent=True, used=True):
        return {"testable": info >= 10.0 and used, "passed": passed, "consistent": consistent, "total": total,
                "info_if_true": info, "used": used}

    def g(*folds):
        return {"folds": list(folds), "folds_passed": sum(f["passed"] for f in folds)}
    assert FOLD_JOIN_NATS < 8.96 < 10.0
    assert 20.48 >= FOLDS_COMBINED_Z * (2 * (12.48 + 8.96)) ** 0.5
    case = g(fold(12.48, 8.96, passed=True), fold(8.0, 12.47), fold(0.65, 2.1))
    assert sc.folds_ok(case)
    # the same gains where only the testable fold carries enough of it: one fold decides, and it did not pass
    assert not sc.folds_ok(g(fold(12.48, 4.0, passed=True), fold(8.0, 12.47), fold(0.65, 2.1)))
    # a joining fold that loses, or gains far more than the candidate could, contradicts it
    assert not sc.folds_ok(g(fold(-1.0, 8.96), fold(8.0, 12.47), fold(0.65, 2.1)))
    assert not sc.folds_ok(g(fold(40.0, 8.96, passed=True, consistent=False), fold(8.0, 12.47)))
    # a fold left out of the pooled interval (its refit undetermined) does not join
    assert not sc.folds_ok(g(fold(12.48, 8.96, passed=True, used=False), fold(8.0, 12.47)))
    # two folds that cannot test it alone carry it together when their sum stands above the scatter
    assert sc.folds_ok(g(fold(9.0, 7.0), fold(8.0, 8.0)))
    assert not sc.folds_ok(g(fold(3.0, 7.0), fold(2.0, 8.0)))


class _Fit:
    """A fitted model as the attribution reads it (no effects of its own, a zero training prediction)."""
    effects = {}
    _ctx = {"pred": np.zeros((4, 5))}


class _FakeModel:
    """An effect model whose first effect has no nonlinear parameter to hold fixed."""

    def __init__(self, *args):
        pass

    def fixed_nonlinear(self, eff):
        return {}


class _FakeScorer:
    """The parts of a Scorer the forward selection touches, without a record behind them."""
    nominal = {"tag": "nominal"}
    nominal_train_pred = np.zeros((4, 5))
    cal = None
    vref_V = 0.45

    class f:
        @staticmethod
        def extra_score_floor(floor):
            return contextlib.nullcontext()


def _fake_attribution(monkeypatch, pair_gain_of_lookalike):
    """Forward selection on fake evaluations: A (accepted) and its look-alike B; C a second effect beside A."""
    import fmvmg_sim.diagnosis.attribute as A

    names = A.DETERMINISTIC
    a, b, c = "q_factor_drift", "reference_drift", "thermal_hysteresis"

    def ev(names_, gain, lo, accepted):
        return {"names": list(names_), "fit": _Fit(), "preds": {"tag": "+".join(sorted(names_))}, "in_bounds": True,
                "gain": {"gain": gain, "ci": [lo, gain + 2.0]}, "accepted": accepted, "delta_bic": -50.0}

    def fake_evaluate(scorer, names_, base, base_pred_train, fixed=None, k_base=0, new=None):
        key = frozenset(names_)
        table = {frozenset({a}): (10.0, 6.0, True), frozenset({b}): (9.5, 5.0, False),
                 frozenset({c}): (1.0, -1.0, False),
                 frozenset({a, c}): (3.0, 1.0, True),                        # C beside A: accepted second
                 frozenset({b, c}): (pair_gain_of_lookalike, 9.0, False)}    # B with C, against the nominal model
        return ev(names_, *table.get(key, (-1.0, -2.0, False)))

    class Scorer(_FakeScorer):
        @staticmethod
        def gain(cand, base):   # the chosen pair A+C over the nominal model
            assert cand["tag"] == "+".join(sorted((a, c))) and base["tag"] == "nominal"
            return {"gain": 13.0, "ci": [11.0, 15.0]}

    monkeypatch.setattr(A, "evaluate", fake_evaluate)
    monkeypatch.setattr(A, "EffectModel", _FakeModel)
    assert a in names and b in names and c in names
    return A.attribute(Scorer(), max_effects=2), a, b, c


def test_forward_selected_pair_reports_the_first_effects_lookalike(monkeypatch):
    att, a, b, c = _fake_attribution(monkeypatch, pair_gain_of_lookalike=12.5)
    assert att["selected"] == [a, c]
    assert att["pair_alternatives"] == {a: [b]}    # B beside C explains the record as well as A beside C


def test_lookalike_that_fails_beside_the_second_effect_is_not_reported(monkeypatch):
    att, a, b, c = _fake_attribution(monkeypatch, pair_gain_of_lookalike=8.0)
    assert att["selected"] == [a, c]
    assert att["pair_alternatives"] == {}


def test_second_effect_rejudged_with_the_records_rate_noise(monkeypatch):
    """Extra flicker found: the second effect is scored again, beside the first alone, with the new noise model."""
    import fmvmg_sim.diagnosis.attribute as A

    a, c = "q_factor_drift", "temperature_rate"
    seen = []

    def fake_evaluate(scorer, names_, base, base_pred_train, fixed=None, k_base=0, new=None):
        rho, K, s = scorer.noise_params[0]
        seen.append((list(names_), list(new), base["tag"]))
        # a term that follows the wander passes only while the noise model holds little slow noise
        return {"names": list(names_), "fit": _Fit(), "preds": {"tag": "pair"}, "in_bounds": True,
                "gain": {"gain": 1.0, "ci": [0.5, 1.5]}, "accepted": K < 0.5, "delta_bic": -20.0}

    class Scorer(_FakeScorer):
        noise_params = [(0.9, 0.1, 1.0)] * 5

    monkeypatch.setattr(A, "evaluate", fake_evaluate)
    monkeypatch.setattr(A, "EffectModel", _FakeModel)
    first = {"fit": _Fit(), "preds": {"tag": "first"}}
    att = {"single": {a: first}, "selected": [a, c], "final": {"tag": "pair"}, "pair_scan": {c: {}},
           "pair_alternatives": {a: ["reference_drift"]}}
    sc = Scorer()
    out = A.rejudge_second(sc, att, 0, (0.99, 0.8, 1.0))
    assert seen == [([a, c], [c], "first")]                       # the pair, scored against the first alone
    assert out["selected"] == [a] and out["final"] is first and out["pair_alternatives"] == {}
    assert out["rejudged"]["effect"] == c and not out["rejudged"]["accepted"]
    assert sc.noise_params[0] == (0.9, 0.1, 1.0) and att["selected"] == [a, c]   # inputs untouched
    kept = A.rejudge_second(sc, att, 0, (0.99, 0.1, 1.0))
    assert kept["selected"] == [a, c] and kept["rejudged"]["accepted"]
    # nothing to judge: one effect, or a pair fitted from scratch (no forward-selected second)
    assert A.rejudge_second(sc, dict(att, selected=[a]), 0, (0.99, 0.8, 1.0))["rejudged"] is None
    assert A.rejudge_second(sc, dict(att, pair_scan={}), 0, (0.99, 0.8, 1.0))["selected"] == [a, c]


def test_reference_drift_without_its_vref_part():
    """The prior's least Vref share: 1e-5/K x 0.45 V against 2 mV/K, i.e. 2.25e-3 of the rectifier part."""
    from fmvmg_sim.diagnosis.attribute import reference_lacks_vref
    assert reference_lacks_vref({"vref_tc_per_K": 2.8e-9, "rectifier_mV_per_K": 3.3e-3}, 0.45)   # a Q drift's fit
    assert not reference_lacks_vref({"vref_tc_per_K": -1.6e-7, "rectifier_mV_per_K": 1.3e-3}, 0.45)  # share 0.055
    # the edge of the prior: the least Vref coefficient beside the largest rectifier drift
    assert not reference_lacks_vref({"vref_tc_per_K": 1.01e-5, "rectifier_mV_per_K": 2.0}, 0.45)
    assert reference_lacks_vref({"vref_tc_per_K": 0.99e-5, "rectifier_mV_per_K": -2.0}, 0.45)
    assert not reference_lacks_vref({"vref_tc_per_K": 0.0, "rectifier_mV_per_K": 0.0}, 0.45)


class _RefFit(_Fit):
    def __init__(self, vref, rect):
        self.effects = {"reference_drift": {"vref_tc_per_K": vref, "rectifier_mV_per_K": rect}}


def _tie(names, gain, lo, accepted=True, fit=None):
    return {"names": list(names), "fit": fit if fit is not None else _Fit(), "accepted": accepted,
            "gain": {"gain": gain, "ci": [lo, gain + 2.0]}}


def test_tied_q_drift_ranks_before_a_reference_drift_without_vref():
    from fmvmg_sim.diagnosis.attribute import prefer_q_drift
    q, r = "q_factor_drift", "reference_drift"
    rect_only, with_vref = _RefFit(3e-9, 3e-3), _RefFit(1.6e-7, 1.3e-3)
    single = {r: _tie([r], 138.9, 130.0, fit=rect_only), q: _tie([q], 138.8, 130.5)}
    assert prefer_q_drift(single, r, 0.45) == q
    assert prefer_q_drift(dict(single, **{r: _tie([r], 138.9, 130.0, fit=with_vref)}), r, 0.45) == r
    assert prefer_q_drift(dict(single, **{q: _tie([q], 125.0, 120.0)}), r, 0.45) == r       # not tied
    assert prefer_q_drift(dict(single, **{q: _tie([q], 138.8, 130.5, accepted=False)}), r, 0.45) == r
    assert prefer_q_drift(single, q, 0.45) == q
    # pairs fitted from scratch: keyed "a+b" (sorted), the mate kept
    m = "stress_relaxation"
    pairs = {f"{r}+{m}": _tie([r, m], 50.0, 40.0, fit=rect_only), f"{q}+{m}": _tie([q, m], 49.0, 41.0)}
    assert prefer_q_drift(pairs, f"{r}+{m}", 0.45) == f"{q}+{m}"
    assert prefer_q_drift(pairs, f"{q}+{m}", 0.45) == f"{q}+{m}"
    both = {f"{q}+{r}": _tie([q, r], 50.0, 40.0, fit=rect_only)}              # a pair of the two: no swap
    assert prefer_q_drift(both, f"{q}+{r}", 0.45) == f"{q}+{r}"


def test_forward_selection_starts_from_the_tied_q_drift(monkeypatch):
    import fmvmg_sim.diagnosis.attribute as A
    q, r = "q_factor_drift", "reference_drift"

    def fake_evaluate(scorer, names_, base, base_pred_train, fixed=None, k_base=0, new=None):
        if list(names_) == [r]:
            return dict(_tie([r], 139.0, 131.0, fit=_RefFit(3e-9, 3e-3)), preds={"tag": r}, in_bounds=True)
        if list(names_) == [q]:
            return dict(_tie([q], 138.8, 131.5), preds={"tag": q}, in_bounds=True)
        return dict(_tie(names_, -1.0, -2.0, accepted=False), preds={"tag": "x"}, in_bounds=True)

    monkeypatch.setattr(A, "evaluate", fake_evaluate)
    monkeypatch.setattr(A, "EffectModel", _FakeModel)
    att = A.attribute(_FakeScorer(), max_effects=2)
    assert att["selected"] == [q]
    assert r in ambiguity(att["single"], q)      # the reference drift stays in the ambiguity set


def test_q_drift_and_a_rectifier_only_reference_drift_are_one_signature():
    from fmvmg_sim.diagnosis.attribute import _refuse_q_and_rectifier
    q, r = "q_factor_drift", "reference_drift"
    both = _tie([q, r], 30.0, 20.0, fit=_RefFit(4e-9, -9e-3))
    _refuse_q_and_rectifier(both, 0.45)
    assert not both["accepted"] and "same signature" in both["why_not"][0]
    true_pair = _tie([q, r], 30.0, 20.0, fit=_RefFit(-3.8e-6, -1.7e-2))   # Vref part 10 % of the rectifier's
    _refuse_q_and_rectifier(true_pair, 0.45)
    assert true_pair["accepted"]
    other = _tie([r, "duffing"], 30.0, 20.0, fit=_RefFit(4e-9, -9e-3))
    _refuse_q_and_rectifier(other, 0.45)
    assert other["accepted"]


def _table_attribution(monkeypatch, table, scratch=False):
    """attribute() on fake evaluations looked up by effect set: ``{frozenset: (gain, lo, accepted, fit)}``."""
    import fmvmg_sim.diagnosis.attribute as A

    def fake_evaluate(scorer, names_, base, base_pred_train, fixed=None, k_base=0, new=None):
        gain, lo, accepted, fit = table.get(frozenset(names_), (-1.0, -2.0, False, None))
        ev = _tie(sorted(names_), gain, lo, accepted=accepted, fit=fit)
        return dict(ev, preds={"tag": "+".join(sorted(names_))}, in_bounds=True, delta_bic=-20.0 if accepted else 0.0)

    class Scorer(_FakeScorer):
        @staticmethod
        def folds_ok(g):
            return True

    monkeypatch.setattr(A, "evaluate", fake_evaluate)
    monkeypatch.setattr(A, "EffectModel", _FakeModel)
    if scratch:   # both members matter in every pair: the refusal and the swap are what is tested
        monkeypatch.setattr(A, "_significant_param", lambda fit, names: True)
        monkeypatch.setattr(A, "_beats", lambda scorer, ev, other: True)
    return A.attribute(Scorer(), max_effects=2)


Q, R, H, S = "q_factor_drift", "reference_drift", "thermal_hysteresis", "stress_relaxation"


def test_forward_selected_second_effect_is_the_tied_q_drift(monkeypatch):
    rect_only = _RefFit(3e-9, 3e-3)
    att = _table_attribution(monkeypatch, {
        frozenset({H}): (50.0, 40.0, True, _Fit()),
        frozenset({H, R}): (5.0, 3.0, True, rect_only),
        frozenset({H, Q}): (4.9, 3.5, True, _Fit())})
    assert att["selected"] == [H, Q]
    assert att["pair_alternatives"] == {Q: [R]}          # the reference drift stays the second's look-alike


def test_q_drift_is_not_paired_with_a_rectifier_only_reference_drift(monkeypatch):
    att = _table_attribution(monkeypatch, {
        frozenset({Q}): (50.0, 40.0, True, _Fit()),
        frozenset({Q, R}): (6.0, 4.0, True, _RefFit(4e-9, -9e-3)),     # the better "second", refused
        frozenset({Q, H}): (3.0, 1.0, True, _Fit())})
    assert att["selected"] == [Q, H]
    assert not att["pair_scan"][R]["accepted"] and "same signature" in att["pair_scan"][R]["why_not"][0]
    assert att["pair_alternatives"] == {}                 # nor reported as a look-alike of the second effect


def test_pair_from_scratch_swaps_in_the_q_drift_and_refuses_q_with_rectifier(monkeypatch):
    rect_only = _RefFit(3e-9, 3e-3)
    weak = (5.0, 1.0, False, _Fit())                      # no single effect passes: pairs from scratch
    att = _table_attribution(monkeypatch, {
        frozenset({Q}): weak, frozenset({R}): (5.0, 1.0, False, rect_only), frozenset({S}): weak,
        frozenset({Q, R}): (55.0, 45.0, True, rect_only),  # the best pair, one signature twice: refused
        frozenset({R, S}): (50.0, 40.0, True, rect_only),
        frozenset({Q, S}): (49.0, 41.0, True, _Fit())}, scratch=True)
    assert sorted(att["selected"]) == sorted([Q, S])
    assert att["pair_scan"]["+".join(sorted((Q, R)))]["same_signature"]
    assert att["pair_alternatives"] == {Q: [R]}          # R beside S is the look-alike; Q beside R is not


def test_temperature_driven_effects_are_constant_on_a_hold():
    """On the forward model each effect of TEMPERATURE_DRIVEN, at the middle of its prior range, leaves a record
    held at one temperature unchanged in time (a constant offset at most), while a ramp moves it; a stress
    relaxation moves a hold too (it acts through time), so it is left out."""
    from fmvmg_sim.diagnosis.attribute import DETERMINISTIC, TEMPERATURE_DRIVEN
    from fmvmg_sim.diagnosis.forward import CHANNELS, predict_device
    from fmvmg_sim.effects import validate_effects
    from fmvmg_sim.scenario import load_scenario
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


def _scorer_stub(Y, S, folds):
    """A :class:`Scorer` on given blocks, white unit-variance noise model, no fitter behind it."""
    from types import SimpleNamespace

    from fmvmg_sim.diagnosis.attribute import Scorer
    from fmvmg_sim.diagnosis.fitting import Fitter

    f = SimpleNamespace(Y=Y, S=S, S_score=S, present=np.ones(Y.shape[1], bool), converter={})
    f.residual = lambda pred, scoring=False, Y=None: Fitter.residual(f, pred, scoring, Y)
    sc = Scorer.__new__(Scorer)
    folds = [dict(fd, scored=fd.get("scored", fd["test"])) for fd in folds]
    sc.f, sc.folds, sc.noise_params = f, folds, [(0.0, 1.0)] * Y.shape[1]
    return sc


def test_a_fold_whose_candidate_refit_is_undetermined_cannot_test_it():
    """Three folds; the candidate is right on two and, on the first, 30 sigma off where its refit's prediction
    is uncertain by 50 sigma (a knob its parameter makes collinear on that short window). That fold is flagged
    from the refit's covariance, left out of the pooled interval and counted neither passed nor testable;
    the two others decide. Scored exactly, the first fold would sink the pooled interval."""
    from fmvmg_sim.diagnosis.attribute import INDETERMINATE_SD
    from fmvmg_sim.diagnosis.fitting import Lin

    n, m = 120, 30
    folds = [{"train": np.arange(n) < 30 + 30 * k, "test": (np.arange(n) >= 30 + 30 * k) & (np.arange(n) < 60 + 30 * k)}
             for k in range(3)]
    rng = np.random.default_rng(2)
    truth = np.where(np.arange(n) >= 30, 3.0, 0.0)[:, None]       # an effect: 3 sigma on every held-out block
    Y = truth + rng.standard_normal((n, 1))
    sc = _scorer_stub(Y, np.ones((n, 1)), folds)
    base = {"folds": [(np.zeros((n, 1)), {}) for _ in folds]}
    lin = Lin(np.zeros((n, 1)), np.ones((n, 1, 1)), ["k"], np.zeros(1), np.array([np.nan]), np.array([-1e3]),
              np.array([1e3]))

    def refit(k):
        wild = k == 0
        pred = truth + (30.0 if wild else 0.0)
        return pred, {}, (lin, np.array([[(5 * INDETERMINATE_SD) ** 2 if wild else 0.01]]))
    calls = iter(range(3))
    cand = sc.fold_predictions(lambda rows: refit(next(calls)))
    assert [fo[2] for fo in cand["folds"]] == [False, True, True]
    g = sc.gain(cand, base)
    assert [f["used"] for f in g["folds"]] == [False, True, True]
    assert g["folds"][0]["total"] < -1e4 and not g["folds"][0]["passed"] and not g["folds"][0]["testable"]
    assert g["folds_passed"] == 2 and g["ci"][0] > 3.0             # 4.5 nats per block expected
    exact = sc.gain({"folds": [(p, e) for p, e, *_ in cand["folds"]]}, base)
    assert exact["ci"][0] < 0 and exact["folds_passed"] == 2
    # when every fold is undetermined, none is left out
    calls = iter([0, 0, 0])
    allwild = sc.gain(sc.fold_predictions(lambda rows: refit(next(calls))), base)
    assert all(f["used"] for f in allwild["folds"]) and allwild["ci"][1] < 0


def test_a_relaxation_below_its_floor_is_refused_only_when_the_data_pull_it_there():
    # a relaxation of 1.36 h fitted at 0.98 h (seed 90070 case 37) is not warm-up: held at the 1 h floor the
    # training chi-square rises by less than PIN_CHI2; one fitted at 0.013 h whose cost rises by 400 is refused
    from types import SimpleNamespace

    from fmvmg_sim.diagnosis.attribute import PIN_CHI2, bounds_verdict
    from fmvmg_sim.diagnosis.model import ModelFit

    def fit(tau, strain):
        mf = ModelFit({"stress_relaxation": {"quad_rel": 2e-4, "tau_h": tau}}, {},
                      SimpleNamespace(cost=100.0), None)
        mf._ctx["cost_at"] = lambda over, rows: 100.0 + (strain if over == {"stress_relaxation": 1.0} else np.nan)
        return mf

    scorer = SimpleNamespace(train=np.ones(4, bool))
    assert bounds_verdict(scorer, fit(0.98, 0.5 * PIN_CHI2)) == (True, None)
    assert bounds_verdict(scorer, fit(0.013, 400.0)) == (False, "a relaxation faster than an hour (warm-up-like)")
    # a fit that cannot re-solve (no cost_at) keeps the floor as it was
    mf = fit(0.98, 0.0)
    del mf._ctx["cost_at"]
    assert bounds_verdict(scorer, mf)[0] is False


def test_rate_blocks_held_out_of_a_fold_trained_on_no_rate_are_not_scored():
    """A fold whose training window holds no applied rate cannot predict the scale factor on its held-out rate
    steps (both refits set it from the prior): those blocks are left out of its score (90083/6: a true
    mode-split drift lost 4789 nats per block there). A fold that trained on a rate step scores them all."""
    from fmvmg_sim.diagnosis.attribute import scored_blocks

    n = 120
    idx = np.arange(n)
    folds = [{"train": idx < 30 + 30 * k, "test": (idx >= 30 + 30 * k) & (idx < 60 + 30 * k)} for k in range(3)]
    rate = np.where((idx >= 40) & (idx < 50), 50.0, 0.0)          # one rate step, inside the first fold's test
    rate[70:75] = -20.0                                           # and one in the second fold's test
    scored = scored_blocks(folds, rate)
    assert np.array_equal(scored[0], folds[0]["test"] & (rate == 0.0))    # trained on no rate: steps dropped
    assert np.array_equal(scored[1], folds[1]["test"])                    # its training holds the first step
    assert np.array_equal(scored[2], folds[2]["test"])
    # no rate anywhere, or none held out: every held-out block is scored (the rule acts on no other record)
    assert all(np.array_equal(s, fd["test"]) for s, fd in zip(scored_blocks(folds, np.zeros(n)), folds))
    late = np.where(idx >= 115, 10.0, 0.0)                        # a step only in the last fold's test
    s_late = scored_blocks(folds, late)
    assert np.array_equal(s_late[2], folds[2]["test"] & (idx < 115)) and np.array_equal(s_late[0], folds[0]["test"])
    # the scorer reads only the scored blocks: a candidate right everywhere but 100 sigma off on the unscored
    # rate blocks (its prior-set scale factor) passes; scored there, it would be sunk
    rng = np.random.default_rng(4)
    truth = np.where(idx >= 30, 3.0, 0.0)[:, None]
    Y = truth + rng.standard_normal((n, 1))
    for fd, s in zip(folds, scored):
        fd["scored"] = s
    sc = _scorer_stub(Y, np.ones((n, 1)), folds)
    base = {"folds": [(np.zeros((n, 1)), {}) for _ in folds]}
    wild = truth + np.where((rate != 0.0)[:, None] & (idx < 60)[:, None], 100.0, 0.0)
    cand = {"folds": [(wild, {}) for _ in folds]}
    g = sc.gain(cand, base)
    assert g["folds_passed"] == 3 and g["ci"][0] > 3.0
    for fd in sc.folds:
        fd["scored"] = fd["test"]
    assert sc.gain(cand, base)["folds"][0]["total"] < -1e4


@pytest.mark.xfail(strict=True, reason="the shipped device's amplifier-bandwidth TC is now the physics brief's low end (-0.2 %/K): this record, drawn for the former device, no longer sets up what the test guards; to be replaced with the calibration's rework")
def test_a_fit_refused_at_a_bound_is_retried_with_the_unidentified_knobs_held(tmp_path):
    """A temperature-rate term near its -2000 deg/h per K/min bound on an oven record with no applied rate (the
    sense gain not identifiable, calibrated at +3 %): with every knob free the joint fit lowers the gain and
    pushes the term past the bound (refused as pinned, the 90147/2 miss); retried with the flagged knobs held at
    their calibrated values it lies inside, is accepted alone and reads the truth to 1.5 %. The report says
    which knobs were held."""
    from fmvmg_sim.diagnosis.pipeline import diagnose
    from fmvmg_sim.diagnosis.report import write_report
    from tests.test_diagnosis_helpers import NOMINAL, oven_record
    g_true = -1995.0
    rec, _ = oven_record(tmp_path, "trate", {"temperature_rate": {"g_dph_per_K_per_min": g_true}},
                         theta={"sense_gain_rel": 0.03, "quadrature_rel": 0.17})
    rep = diagnose(str(rec), str(NOMINAL), n_null=2, progress=False, log=lambda m: None)
    assert not rep["calibration"]["parameters"]["sense_gain_rel"]["identifiable"]
    assert rep["accepted"] == ["temperature_rate"]
    row = rep["ranked"][0]
    assert row["effect"] == "temperature_rate" and "sense_gain_rel" in row["held_knobs"]
    assert abs(row["params"]["g_dph_per_K_per_min"] / g_true - 1.0) < 0.015
    assert row["nominal_shift"]["sense_gain_rel"] == pytest.approx(0.0, abs=1e-9)
    write_report(rep, tmp_path / "rep")
    assert "Fitted with knobs held: temperature_rate (" in (tmp_path / "rep" / "report.md").read_text()


@pytest.mark.parametrize("g_retried, taken", [(2000.0, False), (1998.0, False), (1941.0, True)])
def test_a_retried_fit_is_taken_only_strictly_inside_its_bounds(monkeypatch, g_retried, taken):
    """The retry of a fit refused at a bound is scored only when it lands strictly inside (not within
    PIN_TOLERANCE, 4 deg/h per K/min here, of the +2000 bound): on the bound its parameter has no standard error
    and fails the significance test, so taking it would swap a refusal the pair search can still mend for an
    insignificant single fit (90157/15, session 37)."""
    from types import SimpleNamespace
    from fmvmg_sim.diagnosis import attribute as A
    free = {"fit": None, "in_bounds": False, "bound_reason": A.BOUND_REASON, "held_knobs": []}
    held = {"fit": SimpleNamespace(effects={"temperature_rate": {"g_dph_per_K_per_min": g_retried}}),
            "in_bounds": True, "bound_reason": None, "held_knobs": []}
    monkeypatch.setattr(A, "_evaluate", lambda *a, hold, **k: dict(held if hold else free))
    scorer = SimpleNamespace(cal=SimpleNamespace(identifiable={"sense_gain_rel": False, "quadrature_rel": True}))
    ev = A.evaluate(scorer, ["temperature_rate"], {}, np.zeros(1))
    assert (ev["fit"] is not None) is taken
    assert ev["held_knobs"] == (["sense_gain_rel"] if taken else [])


def _swap_attribution(monkeypatch, first, lookalike, lookalike_fit, pair_gain, pair_accepted=True):
    """Forward selection on fake evaluations: ``first`` (accepted alone) and its look-alike tie, the second effect
    H passes beside ``first``; the forward-selected pair gains 13.0 over the nominal model (interval 11-15), the
    look-alike beside H ``pair_gain``."""
    import fmvmg_sim.diagnosis.attribute as A
    table = {frozenset({first}): (10.0, 6.0, True, _Fit()),
             frozenset({lookalike}): (9.5, 5.0, True, lookalike_fit),
             frozenset({first, H}): (3.0, 1.0, True, _Fit()),             # H beside the first: gains 3 over it
             frozenset({lookalike, H}): (pair_gain, pair_gain - 2.0, pair_accepted, lookalike_fit)}

    def fake_evaluate(scorer, names_, base, base_pred_train, fixed=None, k_base=0, new=None):
        gain, lo, accepted, fit = table.get(frozenset(names_), (-1.0, -2.0, False, None))
        ev = _tie(sorted(names_), gain, lo, accepted=accepted, fit=fit)
        return dict(ev, preds={"tag": "+".join(sorted(names_))}, in_bounds=True, delta_bic=-20.0 if accepted else 0.0)

    class Scorer(_FakeScorer):
        @staticmethod
        def folds_ok(g):
            return True

        @staticmethod
        def gain(cand, base):   # the forward-selected pair over the nominal model
            assert cand["tag"] == "+".join(sorted((first, H))) and base["tag"] == "nominal"
            return {"gain": 13.0, "ci": [11.0, 15.0]}

    monkeypatch.setattr(A, "evaluate", fake_evaluate)
    monkeypatch.setattr(A, "EffectModel", _FakeModel)
    monkeypatch.setattr(A, "_significant_param", lambda fit, names: True)
    monkeypatch.setattr(A, "_beats", lambda scorer, ev, other: True)
    return A.attribute(Scorer(), max_effects=2)


@pytest.mark.parametrize("pair_gain, accepted, swapped", [(14.0, True, True), (12.5, True, False),
                                                           (14.0, False, False)])
def test_a_lookalike_that_makes_the_better_pair_takes_the_first_place(monkeypatch, pair_gain, accepted, swapped):
    m, qd = "mode_split_drift", "quadrature_drift"
    att = _swap_attribution(monkeypatch, m, qd, _Fit(), pair_gain, accepted)
    if swapped:     # the look-alike beside H explains the held-out data better than the first effect beside H
        assert att["selected"] == [qd, H] and att["final"]["names"] == sorted([qd, H])
        assert att["pair_alternatives"] == {qd: [m]}
    else:           # a look-alike pair that gains less, or does not pass, only stays the first effect's look-alike
        assert att["selected"] == [m, H] and att["final"]["names"] == sorted([m, H])
        assert att["pair_alternatives"] == {m: [qd]}


def test_a_reference_drift_without_its_vref_part_does_not_take_the_q_drifts_place(monkeypatch):
    att = _swap_attribution(monkeypatch, Q, R, _RefFit(3e-9, 3e-3), 14.0)
    assert att["selected"] == [Q, H] and att["pair_alternatives"] == {Q: [R]}
    att = _swap_attribution(monkeypatch, Q, R, _RefFit(1.6e-7, 1.3e-3), 14.0)   # with its Vref part it may
    assert att["selected"] == [R, H] and att["pair_alternatives"] == {R: [Q]}
