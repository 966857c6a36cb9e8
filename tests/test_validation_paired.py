"""Paired comparison of two benchmark runs on the same cases (fmvmg_sim.validation.paired)."""

import numpy as np
from scipy.stats import binom

from fmvmg_sim.validation.paired import format_paired, paired_changes


def _rows(outcomes):
    rows = []
    for case, kind, value in outcomes:
        r = {"case": case, "tier": "above", "error": None}
        if kind == "null":
            r["false_alarm"] = value
        elif kind == "single":
            r["top1"] = r["top2"] = value
        else:
            r["pair_exact"] = value
        rows.append(r)
    return rows


def test_changed_outcomes_are_counted_each_way_with_mcnemar():
    before = _rows([(0, "null", False), (1, "null", True), (2, "single", False), (3, "single", True),
                    (4, "single", False), (5, "pair", True), (6, "single", True)])
    after = _rows([(0, "null", True), (1, "null", False), (2, "single", True), (3, "single", True),
                   (4, "single", True), (5, "pair", True), (6, "single", True)])
    after[-1]["error"] = "ValueError: boom"      # a failed diagnosis is left out of the comparison
    p = paired_changes(before, after)
    fa = p["false_alarm"]
    # a false alarm is the wrong outcome: case 0 turned wrong, case 1 turned right
    assert (fa["cases"], fa["right_before"], fa["right_after"], fa["gained"], fa["lost"]) == (2, 1, 1, [1], [0])
    assert fa["p_mcnemar"] == 1.0
    t2 = p["top2"]
    assert (t2["cases"], t2["right_before"], t2["right_after"], t2["gained"], t2["lost"]) == (3, 1, 3, [2, 4], [])
    # exact two-sided binomial on the two discordant cases, both one way: 2 * 0.5 ** 2
    assert np.isclose(t2["p_mcnemar"], 2 * binom.pmf(2, 2, 0.5))
    assert p["pair_exact"]["p_mcnemar"] is None and p["pair_exact"]["gained"] == p["pair_exact"]["lost"] == []
    md = format_paired(p, "runs/a")
    assert "runs/a" in md and "| single effects above the limit: top-2 | 3 | 1 | 3 | 2, 4 | - |" in md


def test_cases_below_the_limit_are_not_compared_for_top2():
    before = _rows([(0, "single", False)])
    before[0]["tier"] = "near"
    after = _rows([(0, "single", True)])
    after[0]["tier"] = "near"
    assert paired_changes(before, after)["top2"]["cases"] == 0
