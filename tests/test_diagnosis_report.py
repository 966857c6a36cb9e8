"""The diagnosis report's Markdown sections."""

from fmvmg_sim.diagnosis.attribution import TEMPERATURE_DRIVEN
from fmvmg_sim.diagnosis.heldout import MIN_TRAIN_SPAN_K
from fmvmg_sim.diagnosis.report import _coverage_lines, design_check, in_sample_lines, markdown, rank_rows


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


def _report(**kw):
    rep = {"verdict": "none", "accepted": [], "ambiguous_with": {}, "ranked": [],
           "localization": {"channels": {}, "allan_bands": {}, "regimes": {}}, "remainder": None,
           "record": {"path": "r.csv", "samples": 10800, "duration_s": 10800.0, "sample_interval_s": 1.0,
                      "channels": ["rate_V"], "issues": {}, "folds": [], "scale_factor_V_per_dps": 0.009},
           "calibration": {"parameters": {}}, "settings": {}, "rules_fired": [], "rules": {"criteria": []}}
    rep.update(kw)
    return rep


def test_record_section_names_what_a_one_temperature_record_cannot_identify():
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


def test_a_record_held_at_one_temperature_cannot_identify_temperature_laws():
    """Every training window at 31.9 C, the last held-out block ramping: the design, not the diagnosis, is why a
    temperature law cannot be found there."""
    cover = lambda *train_C: {"folds": [{"train_C": t} for t in train_C]}  # noqa: E731
    held = design_check(cover([31.9, 31.9], [31.9, 31.9], [31.9, 31.9]))
    assert held["temperature_laws_identifiable"] is False and held["train_span_K"] == 0.0
    assert held["not_identifiable"] == list(TEMPERATURE_DRIVEN)
    assert "stress_relaxation" not in held["not_identifiable"]  # acts through time: a hold shows it
    ramp = design_check(cover(None, [20.0, 20.0 + MIN_TRAIN_SPAN_K], [20.0, 40.0]))
    assert ramp["temperature_laws_identifiable"] is True and ramp["not_identifiable"] == []
    assert design_check(cover([20.0, 20.0 + 0.99 * MIN_TRAIN_SPAN_K]))["temperature_laws_identifiable"] is False


def _row(effect, passed_alone, gain):
    return {"effect": effect, "accepted": passed_alone, "heldout_gain": gain}


def test_the_verdict_ranks_first_then_its_lookalikes_by_gain_then_those_that_passed_alone():
    rows = [_row("mode_split_drift", True, 0.083), _row("quadrature_drift", True, 0.064),
            _row("feedthrough", True, 0.036), _row("demod_phase_drift", False, 0.097),
            _row("temperature_rate", False, -0.008), _row("duffing", False, None)]
    amb = ["demod_phase_drift", "quadrature_drift"]
    out = [r["effect"] for r in rank_rows(rows, ["mode_split_drift"], amb)]
    assert out == ["mode_split_drift", "demod_phase_drift", "quadrature_drift", "feedthrough", "temperature_rate",
                   "duffing"]
    # a second effect that did not pass alone still ranks second
    out = [r["effect"] for r in rank_rows(rows, ["mode_split_drift", "temperature_rate"])]
    assert out[:2] == ["mode_split_drift", "temperature_rate"]
    # nothing accepted: passed alone first, then by gain, a missing gain last
    assert [r["effect"] for r in rank_rows(rows, [])][:3] == ["mode_split_drift", "quadrature_drift", "feedthrough"]


def test_a_statistic_its_null_does_not_describe_is_named_in_the_localisation():
    fd = {"z": -97.3, "p_holm": 1.0, "significant": False, "comparable": False}
    rate = {"z": 0.4, "p_holm": 1.0, "significant": False, "comparable": True}
    rep = _report(localization={"channels": {"rate_V": rate, "drive_frequency_Hz": fd}, "allan_bands": {},
                                "regimes": {}})
    md = markdown(rep)
    assert "| channels | drive_frequency_Hz | -97.30 | 1 | not comparable |" in md
    assert "| channels | rate_V | 0.40 | 1 | no |" in md
    assert "Not comparable: drive_frequency_Hz." in md


def test_the_report_lists_the_rules_that_fired_and_a_law_beyond_its_tolerance():
    law = {"knob": "vref_tc_per_K", "nominal": 2e-5, "calibrated": 6.5e-5, "tolerance": 3e-5, "at_bound": True}
    row = {"effect": "reference_drift", "accepted": True, "params": {"vref_tc_per_K": 3e-5, "rectifier_mV_per_K": 0.0},
           "heldout_gain": 3.0, "heldout_gain_ci": [2.0, 4.0], "law": law}
    cal = {"parameters": {"vref_tc_per_K": {"value": 4.5e-5, "sd": 1e-7, "tolerance": 3e-5, "identifiable": True,
                                            "at_bound": True, "group": "law", "effect": "reference_drift",
                                            "nominal": 2e-5, "calibrated": 6.5e-5, "sd_calibrated": 1e-7}},
           "at_bound": ["vref_tc_per_K"], "not_identifiable": [], "quadrature_sign": -1.0}
    rep = _report(verdict="explained", accepted=["reference_drift"], ranked=[row], calibration=cal,
                  rules_fired=[{"rule": "best_single", "detail": "reference_drift passes"},
                               {"rule": "explained", "detail": "the accepted effects explain the gap"}],
                  rules={"criteria": [{"name": "heldout_interval", "reason": "x"}], "shrink_floor": 0.2})
    md = markdown(rep)
    assert "1. **best_single**: reference_drift passes" in md and "2. **explained**" in md
    assert "reference_drift is the vref_tc_per_K law beyond its tolerance: calibrated at 6.5e-05 against a nominal " \
           "2e-05 (tolerance 3e-05, at its bound)" in md
    assert "| vref_tc_per_K | law | 2e-05 | 6.5e-05 |" in md and "**at its bound** (see reference_drift)" in md
    assert "sign opposite to the device file's" in md and "A temperature law at its bound (vref_tc_per_K)" in md
