"""The acceptance criteria and the decision rules, each on small hand-made evaluations (no fit, no record)."""

from types import SimpleNamespace

import pytest

from fmvmg_sim.diagnosis.criteria import CRITERIA, CRITERIA_BY_NAME, SHRINK_FLOOR, failed_criteria
from fmvmg_sim.diagnosis.evaluation import Evaluation
from fmvmg_sim.diagnosis.heldout import FoldScore, HeldOutGain, together
from fmvmg_sim.diagnosis.rules import (RULES, Ambiguity, Attribution, BestSingle, GapRequired, LocatedGapNamed,
                                       PairClosesGap, PairFromScratch, SecondBesideFirst, SecondRejudged, best_of,
                                       decide, lookalikes, verdict)


def ev(names, gain=1.0, ci=None, folds_ok=True, dbic=-50.0, bound=None, z=10.0, shrink=0.8, new=None, fitted=True):
    """A hand-made evaluation: every criterion passes unless told otherwise."""
    names = tuple(names) if isinstance(names, (list, tuple)) else (names,)
    g = HeldOutGain(gain, list(ci) if ci is not None else [0.8 * gain, 1.2 * gain], folds_ok=folds_ok)
    return Evaluation(names, tuple(new) if new else names, SimpleNamespace(effects={n: {} for n in names})
                      if fitted else None, {"heldout": None}, g, dbic, bound, z, shrink)


class Fake:
    """A stand-in for the candidate fitter: canned evaluations and answers."""

    def __init__(self, seconds=None, pairs=None, beats=True, closes=None, rejudged=None):
        self.seconds, self.pairs = seconds or {}, pairs or {}
        self._beats, self._closes, self._rejudged = beats, closes or {}, rejudged
        self.asked = []

    def beside(self, first, name):
        self.asked.append(("beside", name))
        return self.seconds.get(name) or ev((first.names[0], name), gain=-1.0, ci=[-2, 0], new=(name,))

    def pair(self, a, b):
        self.asked.append(("pair", a, b))
        return self.pairs.get("+".join(sorted((a, b)))) or ev(sorted((a, b)), gain=-1.0, ci=[-2, 0])

    def beats(self, e, other):
        return self._beats

    def closes(self, e):
        return self._closes.get(e.key)

    def rejudged(self, first, second):
        return self._rejudged


def test_a_candidate_passing_everything_is_accepted_and_each_criterion_names_its_own_failure():
    good = ev("feedthrough")
    assert good.accepted and failed_criteria(good) == []
    cases = {"heldout_interval": dict(ci=[-0.1, 2.0]), "folds_agree": dict(folds_ok=False),
             "bic_improves": dict(dbic=-5.0), "within_bounds": dict(bound="a relaxation faster than an hour"),
             "parameter_significant": dict(z=1.5), "explains_heldout_gap": dict(shrink=0.1)}
    for name, kw in cases.items():
        reasons = ev("feedthrough", **kw).reasons
        assert len(reasons) == 1, (name, reasons)
        assert reasons[0].startswith(CRITERIA_BY_NAME[name].reason) or name == "within_bounds"
    assert ev("feedthrough", bound="a relaxation faster than an hour").reasons == ["a relaxation faster than an hour"]
    assert [c.name for c in CRITERIA][0] == "fitted"
    unfitted = ev("feedthrough", fitted=False)
    unfitted.error = "ValueError: no steady oscillation"
    assert unfitted.reasons == ["the fit left the model's domain (ValueError: no steady oscillation)"]


def test_a_candidate_that_trims_a_null_units_noise_is_refused_by_its_heldout_shrink():
    """Every likelihood test passes, as on a unit whose nominal model fits to its noise, but the candidate removes a
    hundredth of the held-out gap: it explains nothing a user could see."""
    tiny = ev("q_factor_drift", gain=0.05, shrink=0.004)
    assert not tiny.accepted and "shrinks the held-out gap by less than" in tiny.reasons[0]
    assert ev("q_factor_drift", shrink=SHRINK_FLOOR).accepted
    assert ev("q_factor_drift", shrink=None).reasons == ["no held-out gap above the noise to explain"]


def test_folds_together_need_each_to_gain_consistently_and_the_sum_to_stand_out():
    f = lambda tot, info, cons=True: FoldScore(tot / 100, [0.0, 1.0], tot, info, cons)  # noqa: E731
    assert together([f(12.0, 12.0), f(9.0, 9.0)])                 # 21 nats against 2 sqrt(2 x 21) = 13
    assert not together([f(12.0, 12.0)])                           # one fold is not "together"
    assert not together([f(12.0, 12.0), f(-1.0, 9.0)])            # one loses
    assert not together([f(12.0, 12.0), f(9.0, 9.0, False)])      # one far from what the candidate predicts
    assert not together([f(3.0, 12.0), f(2.0, 9.0)])              # 5 nats: below 2 sqrt(42)


def test_best_single_takes_the_largest_gain_and_the_simpler_of_two_ties():
    att = Attribution({"quadrature_drift": ev("quadrature_drift", gain=2.0, ci=[1.5, 2.5]),
                       "mode_split_drift": ev("mode_split_drift", gain=1.0),
                       "feedthrough": ev("feedthrough", gain=3.0, folds_ok=False)})
    BestSingle("best_single").apply(att, Fake())
    assert att.selected == ["quadrature_drift"] and att.fired[0]["rule"] == "best_single"
    assert "another effect explains the gap better" in att.notes["mode_split_drift"]
    # a two-parameter effect and a one-parameter effect whose gain reaches its interval: the simpler is chosen
    two = {"reference_drift": ev("reference_drift", gain=1.0, ci=[0.8, 1.2]),
           "q_factor_drift": ev("q_factor_drift", gain=0.9, ci=[0.7, 1.1])}
    assert best_of(list(two.values())).names == ("q_factor_drift",)
    two["q_factor_drift"] = ev("q_factor_drift", gain=0.7, ci=[0.5, 0.9])  # below the interval: no tie
    assert best_of(list(two.values())).names == ("reference_drift",)
    nothing = Attribution({"duffing": ev("duffing", shrink=0.0)})
    BestSingle("best_single").apply(nothing, Fake())
    assert nothing.selected == [] and nothing.fired == []


def test_a_second_effect_joins_when_it_passes_beside_the_first():
    att = Attribution({"thermal_lag": ev("thermal_lag", gain=5.0), "temperature_rate": ev("temperature_rate"),
                       "quadrature_drift": ev("quadrature_drift", gain=0.1, shrink=0.0)})
    second = ev(("thermal_lag", "temperature_rate"), gain=0.5, new=("temperature_rate",))
    BestSingle("best_single").apply(att, Fake())
    SecondBesideFirst("second_beside_first").apply(att, Fake(seconds={"temperature_rate": second}))
    assert att.selected == ["thermal_lag", "temperature_rate"] and att.final is second
    # beside the first, a second that leaves the first's gap where it was does not join
    att2 = Attribution({"thermal_lag": ev("thermal_lag", gain=5.0), "temperature_rate": ev("temperature_rate")})
    BestSingle("best_single").apply(att2, Fake())
    weak = ev(("thermal_lag", "temperature_rate"), gain=0.5, new=("temperature_rate",), shrink=0.05)
    SecondBesideFirst("second_beside_first").apply(att2, Fake(seconds={"temperature_rate": weak}))
    assert att2.selected == ["thermal_lag"]


def test_pairs_from_scratch_only_when_no_single_passes_and_only_a_pair_that_beats_each_member():
    single = {"demod_phase_drift": ev("demod_phase_drift", gain=2.0, z=1.0), "quadrature_drift": ev("quadrature_drift", gain=1.0, z=1.0), "mode_split_drift": ev("mode_split_drift", gain=-1.0, ci=[-2, 0])}
    pair = ev(("demod_phase_drift", "quadrature_drift"), gain=4.0)
    att = Attribution(dict(single))
    PairFromScratch("pair_from_scratch").apply(att, Fake(pairs={"demod_phase_drift+quadrature_drift": pair}))
    assert att.selected == ["demod_phase_drift", "quadrature_drift"] and att.final is pair
    att = Attribution(dict(single))
    PairFromScratch("pair_from_scratch").apply(att, Fake(pairs={"demod_phase_drift+quadrature_drift": pair}, beats=False))
    assert att.selected == []
    done = Attribution(dict(single), selected=["demod_phase_drift"], final=single["demod_phase_drift"])
    fake = Fake(pairs={"demod_phase_drift+quadrature_drift": pair})
    PairFromScratch("pair_from_scratch").apply(done, fake)
    assert done.selected == ["demod_phase_drift"] and fake.asked == []


def test_a_located_gap_is_named_by_an_effect_failing_only_the_fold_count():
    single = {"demod_phase_drift": ev("demod_phase_drift", gain=0.5, folds_ok=False), "quadrature_drift": ev("quadrature_drift", gain=0.9, folds_ok=False, dbic=0.0)}
    att = Attribution(dict(single), located_gap=True)
    LocatedGapNamed("located_gap_named").apply(att, Fake())
    assert att.selected == ["demod_phase_drift"] and "fold count" in att.notes["demod_phase_drift"]
    att = Attribution(dict(single), located_gap=False)  # nothing says there is a gap: the fold count stands
    LocatedGapNamed("located_gap_named").apply(att, Fake())
    assert att.selected == []


def test_a_pair_replaces_a_single_effect_that_leaves_the_located_gap_open_only_when_it_closes_it():
    single = {"demod_phase_drift": ev("demod_phase_drift", gain=2.0), "quadrature_drift": ev("quadrature_drift", gain=1.0)}
    pair = ev(("demod_phase_drift", "quadrature_drift"), gain=3.0)
    att = Attribution(dict(single), selected=["quadrature_drift"], final=single["quadrature_drift"])
    PairClosesGap("pair_closes_gap").apply(att, Fake(pairs={"demod_phase_drift+quadrature_drift": pair}, closes={"quadrature_drift": False, "demod_phase_drift+quadrature_drift": True}))
    assert att.selected == ["demod_phase_drift", "quadrature_drift"] and "leaves the located gap open" in att.notes["quadrature_drift"]
    att = Attribution(dict(single), selected=["quadrature_drift"], final=single["quadrature_drift"])
    PairClosesGap("pair_closes_gap").apply(att, Fake(pairs={"demod_phase_drift+quadrature_drift": pair}, closes={"quadrature_drift": False, "demod_phase_drift+quadrature_drift": False}))
    assert att.selected == ["quadrature_drift"]
    att = Attribution(dict(single), selected=["quadrature_drift"], final=single["quadrature_drift"])  # the single effect closes it: nothing to do
    PairClosesGap("pair_closes_gap").apply(att, Fake(pairs={"demod_phase_drift+quadrature_drift": pair}, closes={"quadrature_drift": True, "demod_phase_drift+quadrature_drift": True}))
    assert att.selected == ["quadrature_drift"]


def test_a_second_effect_that_fails_with_the_records_own_rate_noise_is_dropped():
    first = ev("thermal_lag", gain=5.0)
    att = Attribution({"thermal_lag": first}, selected=["thermal_lag", "temperature_rate"],
                      final=ev(("thermal_lag", "temperature_rate"), new=("temperature_rate",)))
    SecondRejudged("second_rejudged").apply(att, Fake(rejudged=ev(("thermal_lag", "temperature_rate"),
                                                                   ci=[-0.1, 1.0], new=("temperature_rate",))))
    assert att.selected == ["thermal_lag"] and att.final is first and "own rate noise" in att.notes["temperature_rate"]
    att = Attribution({"thermal_lag": first}, selected=["thermal_lag", "temperature_rate"],
                      final=ev(("thermal_lag", "temperature_rate"), new=("temperature_rate",)))
    SecondRejudged("second_rejudged").apply(att, Fake(rejudged=None))  # no extra flicker: no cause to rejudge
    assert att.selected == ["thermal_lag", "temperature_rate"]


def test_the_ambiguity_set_is_every_effect_whose_gain_reaches_the_accepted_ones_interval():
    single = {"mode_split_drift": ev("mode_split_drift", gain=1.0, ci=[0.8, 1.2]),
              "demod_phase_drift": ev("demod_phase_drift", gain=1.1, z=1.0),        # fails alone, still a look-alike
              "quadrature_drift": ev("quadrature_drift", gain=0.9),
              "feedthrough": ev("feedthrough", gain=0.5),                            # below the interval
              "duffing": ev("duffing", gain=1.0, bound="pinned")}                    # inadmissible
    assert {e.names[0] for e in lookalikes(single, single["mode_split_drift"])} == {"demod_phase_drift",
                                                                                   "quadrature_drift"}
    att = Attribution(single, selected=["mode_split_drift"], final=single["mode_split_drift"])
    Ambiguity("ambiguity").apply(att, Fake())
    assert sorted(att.ambiguous["mode_split_drift"]) == ["demod_phase_drift", "quadrature_drift"]
    assert "look-alike of mode_split_drift" in att.notes["quadrature_drift"]
    # a pair fitted from scratch: a pair sharing one member and explaining the record as well
    a, b, c, d = "demod_phase_drift", "quadrature_drift", "mode_split_drift", "feedthrough"
    pairs = {f"{a}+{b}": ev((a, b), gain=2.0, ci=[1.5, 2.5]), f"{a}+{c}": ev((a, c), gain=1.8),
             f"{b}+{d}": ev((b, d), gain=1.9)}
    att = Attribution({n: ev(n) for n in (a, b, c, d)}, pairs=pairs, selected=[a, b], final=pairs[f"{a}+{b}"])
    Ambiguity("ambiguity").apply(att, Fake())
    assert att.ambiguous == {b: [c], a: [d]}


def test_an_effect_is_attributed_only_where_the_localisation_locates_a_gap():
    single = {"temperature_rate": ev("temperature_rate", gain=0.05, ci=[0.03, 0.07])}
    att = decide(Attribution(dict(single), located_gap=False), Fake())
    assert att.selected == [] and att.final is None and "gap_required" in [r["rule"] for r in att.fired]
    assert "null band" in att.notes["temperature_rate"]
    assert verdict(att.selected, att.ambiguous, False, False).verdict == "none"
    # a pair selected without a located gap goes as well; with one, the rule does nothing
    pair = Attribution(dict(single), selected=["thermal_lag", "temperature_rate"], final=ev(("thermal_lag",
                                                                                          "temperature_rate")))
    GapRequired("gap_required").apply(pair, Fake())
    assert pair.selected == [] and set(pair.notes) == {"thermal_lag", "temperature_rate"}
    kept = decide(Attribution(dict(single), located_gap=True), Fake())
    assert kept.selected == ["temperature_rate"] and "gap_required" not in [r["rule"] for r in kept.fired]


def test_the_rules_run_in_order_and_say_which_fired():
    single = {"feedthrough": ev("feedthrough", gain=2.0), "duffing": ev("duffing", gain=0.1, shrink=0.01)}
    att = decide(Attribution(single, located_gap=True), Fake())
    assert att.selected == ["feedthrough"] and [r["rule"] for r in att.fired] == ["best_single"]
    assert [r.name for r in RULES][:2] == ["best_single", "second_beside_first"]


@pytest.mark.parametrize("accepted, amb, located, left_open, expected", [
    ([], {}, False, False, "none"), ([], {}, True, False, "unexplained"), (["a"], {}, True, True, "unexplained"),
    (["a"], {"a": ["b"]}, True, False, "ambiguous"), (["a"], {}, True, False, "explained"),
    (["a"], {}, False, False, "explained")])
def test_verdict(accepted, amb, located, left_open, expected):
    v = verdict(accepted, amb, located, left_open)
    assert v.verdict == expected and v.rule and v.detail
