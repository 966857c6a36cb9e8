"""The diagnosis report's Markdown sections."""

from fmvmg_sim.diagnosis.report import in_sample_lines


def test_in_sample_section_reads_each_held_out_outcome_and_missing_numbers():
    hint = {"note": "not an attribution", "candidates": [
        {"effect": "thermal_hysteresis", "params": {"quad_rel": 0.000466, "width_K": 6.44}, "delta_bic": -6104.4,
         "heldout": {"folds_testable": 0, "gain": 0.0, "ci": [0.0, 0.0]}},
        {"effect": "quadrature_drift", "params": {"beta_per_K": 2.6e-05}, "delta_bic": -5431.3,
         "heldout": {"folds_testable": 1, "gain": -12.5, "ci": [-64312.9, 0.0]}},
        # a held-out fit that failed: JSON-clean infinities are None
        {"effect": "duffing", "params": {"k3_rel": None}, "delta_bic": -20.0,
         "heldout": {"folds_testable": 2, "gain": None, "ci": [None, None]}},
        {"effect": "feedthrough", "params": {"c_ft_fF": 0.04}, "delta_bic": -15.0, "heldout": {}}]}
    L = in_sample_lines(hint)
    assert L[0] == "## In-sample candidates (not an attribution)"
    rows = [ln for ln in L if ln.startswith("- ")]
    assert rows[0] == ("- thermal_hysteresis: Delta-BIC -6104.4, parameters quad_rel = 0.000466, width_K = 6.44; "
                       "no held-out fold can test it")
    assert rows[1].endswith("tested held out, not accepted (gain -12.5 per block, interval [-6.43e+04, 0])")
    assert rows[2].endswith("k3_rel = -; tested held out, not accepted (gain - per block, interval [-, -])")
    assert rows[3].endswith("not scored held out")
    assert in_sample_lines(None) == []
    assert "- none: no library effect closes the gap in-sample either." in in_sample_lines({"candidates": []})


def test_record_section_names_what_a_one_temperature_record_cannot_identify():
    from fmvmg_sim.diagnosis.pipeline import design_check
    from fmvmg_sim.diagnosis.report import _coverage_lines
    folds = [{"train_C": [31.9, 31.9], "test_C": [31.9, 31.9], "train_blocks": 389, "test_blocks": 216,
              "test_outside_fraction": 0.0, "test_start_s": 4320.0}]
    rec = {"folds": folds}
    text = "\n".join(_coverage_lines(rec, {"min_train_span_K": 5.0}, design_check({"folds": folds})))
    assert "No fold's training window spans 5 K" in text and "well before 4320 s" in text
    assert "Not identifiable from this record: thermal_lag, " in text and "reference_drift." in text
    # a record that ramps in training gets neither paragraph
    folds[0]["train_C"] = [20.0, 40.0]
    text = "\n".join(_coverage_lines(rec, {"min_train_span_K": 5.0}, design_check({"folds": folds})))
    assert "Not identifiable" not in text and "No fold's training window" not in text


def test_a_fold_left_unscored_says_why():
    from fmvmg_sim.diagnosis.report import _coverage_lines
    fold = {"train_C": [20.0, 60.0], "test_C": [60.0, 40.0], "train_blocks": 389, "test_blocks": 216,
            "test_outside_fraction": 0.0, "test_start_s": 4320.0}
    folds = [dict(fold, rate_blocks_unscored=216), dict(fold, train_C=[30.0, 32.0], rate_blocks_unscored=0),
             dict(fold, rate_blocks_unscored=51)]
    rows = [ln for ln in _coverage_lines({"folds": folds}, {"folds_not_scored": [0, 1], "min_train_span_K": 5.0})
            if ln.startswith("| ") and ln[2].isdigit()]
    assert "every held-out block is a rate-table step" in rows[0] and "spans under" not in rows[0]
    assert "its training window spans under 5 K" in rows[1]
    assert "(not scored:" not in rows[2] and "51 rate-table blocks not scored" in rows[2]


def test_undetermined_folds_are_named_beside_the_fold_counts():
    from fmvmg_sim.diagnosis.report import _undetermined
    assert _undetermined({"folds_undetermined": 1}) == " (1 undetermined)"
    assert _undetermined({"folds_undetermined": 0}) == "" and _undetermined({}) == ""


def test_the_undetermined_note_reads_its_threshold_from_the_settings():
    from fmvmg_sim.diagnosis.report import markdown
    row = {"effect": "thermal_hysteresis", "accepted": True, "params": {"quad_rel": -5.7e-4}, "heldout_gain": 34.3,
           "heldout_gain_ci": [12.5, 57.4], "folds_passed": 2, "folds_testable": 2, "folds_undetermined": 1,
           "delta_bic": -5.7e4, "gap_before": 9.96, "gap_after": 21.97, "shrink": -3.86, "why_not": []}
    rep = {"verdict": "explained", "accepted": ["thermal_hysteresis"], "ambiguous_with": {}, "ranked": [row],
           "localization": {"channels": {}, "allan_bands": {}, "regimes": {}}, "remainder": None,
           "record": {"path": "r.csv", "samples": 10800, "duration_s": 10800.0, "sample_interval_s": 1.0,
                      "channels": ["rate_V"], "issues": {}, "folds": []},
           "calibration": {"parameters": {}}, "settings": {"indeterminate_sd": 7.5}}
    md = markdown(rep)
    assert "| 2 / 2 (1 undetermined) |" in md
    assert "uncertain by more than 7.5 noise sigmas" in md


def test_a_statistic_its_null_does_not_describe_is_named_in_the_localisation():
    from fmvmg_sim.diagnosis.report import markdown
    fd = {"z": -97.3, "p_holm": 1.0, "significant": False, "comparable": False}
    rate = {"z": 0.4, "p_holm": 1.0, "significant": False, "comparable": True}
    rep = {"verdict": "none", "accepted": [], "ambiguous_with": {}, "ranked": [],
           "localization": {"channels": {"rate_V": rate, "drive_frequency_Hz": fd}, "allan_bands": {}, "regimes": {}},
           "remainder": None,
           "record": {"path": "r.csv", "samples": 10800, "duration_s": 10800.0, "sample_interval_s": 1.0,
                      "channels": ["rate_V"], "issues": {}, "folds": []},
           "calibration": {"parameters": {}}, "settings": {}}
    md = markdown(rep)
    assert "| channels | drive_frequency_Hz | -97.30 | 1 | not comparable |" in md
    assert "| channels | rate_V | 0.40 | 1 | no |" in md
    assert "Not comparable: drive_frequency_Hz." in md
    # a report written before the flag existed reads as before
    del fd["comparable"]
    assert "Not comparable" not in markdown(rep)


def test_a_replaced_first_effect_is_named_with_both_pair_gains():
    from fmvmg_sim.diagnosis.report import replaced_first_lines
    L = replaced_first_lines({"effect": "quadrature_drift", "by": "mode_split_drift", "pair_gain_before": 4.37,
                              "pair_gain_after": 4.402})
    assert L[0].startswith("mode_split_drift replaces quadrature_drift, which forward selection chose first")
    assert "(4.40 against 4.37 nats per held-out block" in L[0] and L[-1] == ""
    assert replaced_first_lines(None) == []
