"""The harness that scores the diagnosis on labelled records made elsewhere: its scoring, table and command."""

import json

import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.diagnosis.criteria import SHRINK_FLOOR
from fmvmg_sim.errors import InputError
from fmvmg_sim.validation.independent import (feedthrough_dps_per_fF, format_table, limit_ratios, load_labels,
                                              score_case, summary)


def _report(verdict, accepted=(), amb=None, shrink=0.9):
    return {"verdict": verdict, "accepted": list(accepted), "ambiguous_with": amb or {},
            "ranked": [{"effect": a, "shrink": shrink} for a in accepted], "rules_fired": [{"rule": "x"}]}


def test_a_null_unit_is_right_only_with_verdict_none():
    null = {"effects": {}}
    assert score_case(null, _report("none"))["right"]
    assert not score_case(null, _report("unexplained"))["right"]
    assert not score_case(null, _report("explained", ["q_factor_drift"]))["right"]
    assert score_case(null, {"error": "ValueError: x"})["error"] == "ValueError: x"


def test_a_single_effect_is_right_first_or_in_the_accepted_effects_ambiguity_set():
    lab = {"effects": {"mode_split_drift": {"split_Hz_per_K": 0.02}}, "strength": {"mode_split_drift": "clear"}}
    assert score_case(lab, _report("explained", ["mode_split_drift"]))["right"]
    assert score_case(lab, _report("ambiguous", ["quadrature_drift"], {"quadrature_drift": ["mode_split_drift"]}))["right"]
    assert not score_case(lab, _report("explained", ["quadrature_drift", "mode_split_drift"]))["right"]
    assert not score_case(lab, _report("none"))["right"]


def test_accepted_effects_below_the_shrink_floor_are_counted():
    lab = {"effects": {"feedthrough": {}}, "strength": {"feedthrough": "clear"}}
    row = score_case(lab, _report("explained", ["feedthrough", "flicker_noise"], shrink=0.5 * SHRINK_FLOOR))
    assert row["below_floor"] == ["feedthrough"]          # a noise-level effect has no deterministic shrink
    rows = {"a": row, "b": score_case({"effects": {}}, _report("none")),
            "c": score_case({"effects": {"a": {}, "b": {}}}, _report("explained", ["b", "a"]))}
    s = summary(rows)
    assert s["null"] == {"right": 1, "cases": 1} and s["single_clear"] == {"right": 1, "cases": 1}
    assert s["pair"] == {"right": 1, "cases": 1} and s["accepted_below_floor"] == 1 and s["errors"] == 0
    table = format_table({"shrink_floor": SHRINK_FLOOR, "scenarios": {"nominal_a": {"rows": rows, "summary": s}}})
    assert "| a | feedthrough (clear) | explained | feedthrough (0.10); flicker_noise | ? | yes |" in table
    assert "| nominal_a | 1 / 1 | 1 / 1 | 0 / 0 | 1 / 1 | 1 / 1 | 1 | 0 |" in table


def _limits(**params):
    return {"detection_limits": {"effects": {e: {"params": p} for e, p in params.items()}}}


def test_a_true_effect_is_measured_against_the_detection_limit_in_the_reports_units():
    """deg/s per K/s is 60 deg/h per K/min, rad is 1e6 urad, ppm is 1e-6; a feedthrough in deg/s is turned into fF
    by the scenario's own sensitivity; a missing label parameter or limit is not guessed."""
    lab = {"effects": {"temperature_rate": {"g_dps_per_K_per_s": -2.0}, "demod_phase_drift": {"kappa_rad_per_K": 5e-5},
                       "reference_drift": {"vref_ppm_per_K": 30.0}, "feedthrough": {"magnitude_dps": 4.0},
                       "duffing": {}, "quadrature_drift": {"beta_per_K": 1e-3}}}
    rep = _limits(temperature_rate={"g_dph_per_K_per_min": 60.0}, demod_phase_drift={"kappa_urad_per_K": 100.0},
                  reference_drift={"vref_tc_per_K": 1e-5, "rectifier_mV_per_K": 0.2}, feedthrough={"c_ft_fF": 0.5},
                  duffing={"k3_rel": 1e-3})
    r = limit_ratios(lab, rep, dps_per_fF=20.0)
    assert r["temperature_rate"] == pytest.approx(2.0) and r["demod_phase_drift"] == pytest.approx(0.5)
    assert r["reference_drift"] == pytest.approx(3.0) and r["feedthrough"] == pytest.approx(0.4)
    assert r["duffing"] is None and r["quadrature_drift"] is None
    assert limit_ratios(lab, rep)["feedthrough"] is None
    below = {"effects": {"mode_split_drift": {"split_Hz_per_K": 0.02}}, "strength": {"mode_split_drift": "clear"}}
    row = score_case(below, dict(_report("none"), **_limits(mode_split_drift={"split_Hz_per_K": 0.04})))
    above = score_case(below, dict(_report("none"), **_limits(mode_split_drift={"split_Hz_per_K": 0.01})))
    assert row["limit_ratio"] == {"mode_split_drift": pytest.approx(0.5)} and not row["right"]
    s = summary({"a": row, "b": above})
    assert s["single_clear"] == {"right": 0, "cases": 2} and s["single_clear_above_limit"] == {"right": 0, "cases": 1}
    flick = score_case({"effects": {"flicker_noise": {"extra_plateau_dps": 0.01}}}, _report("none"))
    assert "| n/a |" in format_table({"shrink_floor": SHRINK_FLOOR, "scenarios": {"s": {"rows": {"f": flick},
                                                                                    "summary": summary({"f": flick})}}})


def test_the_feedthrough_sensitivity_is_the_pickoff_physics():
    """A drive-to-sense feedthrough capacitance of 1 fF on config A reads about 22 deg/s at the rate output (the
    independent generator's model states 1-10 fF as 22-220 deg/s, single-ended)."""
    assert feedthrough_dps_per_fF("nominal_a") == pytest.approx(22.0, rel=0.05)


def test_labels_must_name_each_record_and_its_effects(tmp_path):
    with pytest.raises(InputError, match="no labels.json"):
        load_labels(tmp_path)
    (tmp_path / "labels.json").write_text("{")
    with pytest.raises(InputError, match="not JSON"):
        load_labels(tmp_path)
    (tmp_path / "labels.json").write_text(json.dumps({"case_000": {"effects": {}}}))
    with pytest.raises(InputError, match="no record case_000.csv"):
        load_labels(tmp_path)
    (tmp_path / "case_000.csv").write_text("time_s,temperature_C,rate_dps\n")
    assert load_labels(tmp_path)["case_000"]["record"].endswith("case_000.csv")
    (tmp_path / "labels.json").write_text(json.dumps({"case_000": {"strength": {}}}))
    with pytest.raises(InputError, match="without an 'effects' table"):
        load_labels(tmp_path)


def test_the_command_refuses_bad_input_with_exit_2(tmp_path, capsys):
    rc = main(["diagnose-independent", str(tmp_path / "nope")])
    assert rc == 2 and "not a folder" in capsys.readouterr().err
    rc = main(["diagnose-independent", str(tmp_path)])
    assert rc == 2 and "no labels.json" in capsys.readouterr().err
    (tmp_path / "labels.json").write_text(json.dumps({"case_000": {"effects": {}}}))
    (tmp_path / "case_000.csv").write_text("time_s,temperature_C,rate_dps\n")
    rc = main(["diagnose-independent", str(tmp_path), "--scenario", "no_such_scenario", "-o", str(tmp_path / "o")])
    assert rc == 2 and not (tmp_path / "o").exists()
