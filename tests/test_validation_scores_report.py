"""The benchmark's readable summary: targets against measured values, counts, tiers and misses by cause."""

import pytest

from fmvmg_sim.validation.scoring import score
from fmvmg_sim.validation.scores_report import format_scores


def _res(verdict, accepted=()):
    return {"verdict": verdict, "accepted": list(accepted), "ranked": list(accepted), "ambiguous_with": {},
            "rows": {a: {"shrink": 0.9, "params": {}, "accepted": True, "folds_testable": 3, "why_not": []}
                     for a in accepted}}


def test_summary_reads_targets_counts_and_causes():
    labs = [{"case": 0, "effects": {}, "tier": "null", "snr": 0.0},
            {"case": 1, "effects": {}, "tier": "null", "snr": 0.0},
            {"case": 2, "effects": {"thermal_lag": {}}, "tier": "above", "snr": 50.0},
            {"case": 3, "effects": {"feedthrough": {}}, "tier": "above", "snr": 50.0},
            {"case": 4, "effects": {"duffing": {}, "feedthrough": {}}, "tier": "above", "snr": 50.0}]
    results = [_res("none"), _res("unexplained"), _res("explained", ["thermal_lag"]), _res("none"),
               _res("explained", ["duffing", "feedthrough"])]
    sc = dict(score(labs, results), seed=7)
    md = format_scores(sc)
    lines = md.splitlines()
    assert lines[0] == "# Diagnosis benchmark: 5 cases, seed 7"
    row = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in lines if ln.startswith("| ")}
    # one false alarm of two nulls: 0.5, not met, and its 95 % interval (0.095-0.905) lies wholly above 0.05;
    # top-1 one of two singles: not met, but the interval reaches past 0.9, so not decided; the pair exact
    assert row["false alarms (null cases)"] == ["0.500", "1 of 2", "0.095-0.905", "<= 0.05", "no (decided)"]
    assert row["top-1, single effects above the limit"] == ["0.500", "1 of 2", "0.095-0.905", ">= 0.9", "no"]
    assert row["exact pairs"] == ["1.000", "1 of 1", "0.207-1.000", ">= 0.7", "yes"]
    assert row["median held-out shrink when right"][0] == "0.900"
    # the two singles above the limit (SNR 50) in their SNR band, with intervals; empty bands left out
    assert row["50-100"] == ["2", "0.500 (0.095-0.905)", "0.500 (0.095-0.905)"]
    assert not any(k in row for k in ("< 20", "20-50", ">= 100"))
    # the missed feedthrough (no row: never fitted) is counted under the acceptance criteria
    crit = [v for k, v in row.items() if k.startswith("criteria")]
    assert crit == [["1", "0", "0"]]
    assert not any(k.startswith("look_alike") for k in row)  # causes with no miss are left out


def test_summary_of_an_empty_selection_has_no_verdict():
    sc = score([{"case": 0, "effects": {}, "tier": "null", "snr": 0.0}], [_res("none")])
    md = format_scores(sc)
    assert "| top-1, single effects above the limit | - | - | - | >= 0.9 | - |" in md
    assert "| false alarms (null cases) | 0.000 | 0 of 1 | 0.000-0.793 | <= 0.05 | yes |" in md
    assert "No single effect above the limit and no pair member was missed." in md


def test_summary_shows_the_separable_pairs_beside_the_target():
    labs = [{"case": 0, "effects": {"duffing": {}, "feedthrough": {}}, "tier": "above", "snr": 50.0,
             "tier_separable": "above"},
            {"case": 1, "effects": {"q_factor_drift": {}, "reference_drift": {}}, "tier": "above", "snr": 50.0,
             "tier_separable": "below"}]
    sc = score(labs, [_res("explained", ["duffing", "feedthrough"]), _res("explained", ["reference_drift"])])
    md = format_scores(sc)
    row = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in md.splitlines()
           if ln.startswith("| ")}
    assert row["exact pairs"][:2] == ["0.500", "1 of 2"]
    assert row["exact pairs, both members above the limit beside the other (separable)"] == ["1.000", "1 of 1"]


def test_summary_splits_single_effects_by_the_training_window():
    labs = [{"case": 0, "effects": {"temperature_rate": {}}, "tier": "above", "snr": 28.0, "tier_train": "near",
             "snr_train": 5.0},
            {"case": 1, "effects": {"duffing": {}}, "tier": "above", "snr": 40.0, "tier_train": "above",
             "snr_train": 39.0}]
    sc = score(labs, [_res("unexplained"), _res("explained", ["duffing"])])
    md = format_scores(sc)
    row = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in md.splitlines()
           if ln.startswith("| ")}
    assert row["above the limit there too"] == ["1", "1.000 (0.207-1.000)", "1.000 (0.207-1.000)"]
    assert row["below the limit there"] == ["1", "0.000 (0.000-0.793)", "0.000 (0.000-0.793)"]
    # labels without a training tier (runs before it existed) leave the table out
    old = score([{k: v for k, v in lb.items() if k not in ("tier_train", "snr_train")} for lb in labs],
                [_res("unexplained"), _res("explained", ["duffing"])])
    assert "above the limit there too" not in format_scores(old)


def test_summary_counts_where_the_record_design_note_fired():
    # the note should fire where the truth's evidence lies after the training window (a miss whose training
    # window carries it below the limit) and stay silent where the truth was found or nothing acts
    def res(verdict, accepted=(), fires=False):
        return dict(_res(verdict, accepted), design={"not_identifiable": [], "gap_after_training": {"fires": fires}})
    labs = [{"case": 0, "effects": {}, "tier": "null", "snr": 0.0},
            {"case": 1, "effects": {"temperature_rate": {}}, "tier": "above", "snr": 28.0, "tier_train": "near",
             "snr_train": 5.0},
            {"case": 2, "effects": {"duffing": {}}, "tier": "above", "snr": 40.0, "tier_train": "above",
             "snr_train": 39.0},
            {"case": 3, "effects": {"feedthrough": {}}, "tier": "above", "snr": 30.0, "tier_train": "above",
             "snr_train": 29.0}]
    sc = score(labs, [res("none"), res("unexplained", fires=True), res("explained", ["duffing"]), res("none")])
    assert sc["after_training_note"] == {"null": {"fired": 0, "cases": 1},
                                         "miss_train_below": {"fired": 1, "cases": 1},
                                         "miss_train_above": {"fired": 0, "cases": 1},
                                         "hit": {"fired": 0, "cases": 1}}
    md = format_scores(sc)
    row = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in md.splitlines()
           if ln.startswith("| ")}
    assert row["top-2 misses above the limit, training window below it"] == ["1 of 1"]
    assert row["null cases"] == ["0 of 1"]
    # results from before the note (no "gap_after_training") leave the table out
    assert "| null cases |" not in format_scores(score(labs, [_res("none")] * 4))


def test_summary_reads_the_detection_claim():
    """Single effects against their report's detection limit: the claim's row and the bands."""
    lim = {"power": 0.9, "effects": {"duffing": {"params": {"k3_rel": 1e-4}}}}
    labs = [{"case": k, "effects": {"duffing": {"k3_rel": v}}, "tier": "above", "snr": 20.0}
            for k, v in enumerate((3e-4, 1.5e-4, 2e-5))]
    results = [dict(_res("explained", ["duffing"]), detection_limits=lim),
               dict(_res("none"), detection_limits=lim), dict(_res("none"), detection_limits=lim)]
    sc = score(labs, results)
    assert [r["mde_ratio"] for r in sc["rows"]] == pytest.approx([3.0, 1.5, 0.2])
    rows = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]]
            for ln in format_scores(sc).splitlines() if ln.startswith("| ")}
    assert rows[">= 1 (the claim)"] == ["2", "0.500 (0.095-0.905)", "0.500 (0.095-0.905)"]
    assert rows["< 1"][:2] == ["1", "0.000 (0.000-0.793)"]
    assert rows["2-5"][0] == "1" and rows["1-2"][0] == "1" and "0.5-1" not in rows
