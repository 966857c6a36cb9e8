"""The validation page's machinery: a section measured and written whole, bad options refused."""

import json

import pytest

from fmvmg_sim.validation import page
from fmvmg_sim.validation.independent import score_case, summary


def test_a_section_is_measured_and_written_with_its_numbers(tmp_path):
    out = tmp_path / "v" / "validation.md"
    assert page.main(["--only", "allan", "-o", str(out), "--json", str(out.with_suffix(".json"))]) == 0
    md = out.read_text()
    assert md.startswith("# Validation") and "## Allan analysis against Stable32 and NIST" in md
    data = json.loads(out.with_suffix(".json").read_text())
    # our Allan deviation reproduces Stable32's on all 273 taus of the OCXO record to 1e-4
    assert data["allan"]["OCXO, all 273 taus"]["taus"] == 273
    assert data["allan"]["OCXO, all 273 taus"]["max_rel_diff"] < 1e-4


@pytest.mark.parametrize("argv", [["--only", "nonsense"], ["--only", "allan", "-o", str(page.REPO / "docs" / "validation.md")]])
def test_bad_options_are_refused_before_measuring(argv, capsys):
    assert page.main(argv) == 2
    assert capsys.readouterr().err.strip()


def test_the_compensation_section_holds_the_default_method_to_the_better_baseline():
    """On the measured records the default method is within 1.05 x the better of a line in T and the
    selected polynomial, and the section says where the line wins."""
    sec = page.compensation_records(quick=True, log=lambda m: None)
    assert sec.data["pairs"] >= 20
    assert sec.data["default_within_1p05_of_best"] == sec.data["pairs"]
    text = "\n".join(sec.lines)
    assert "| record | fitted -> applied |" in text and ("line wins" in text) == (sec.data["line_wins"] > 0)


def test_the_diagnosis_section_tabulates_a_finished_run_without_its_record_names(tmp_path):
    """The opt-in diagnosis section reads a harness output folder, numbers the records (no file names on the page)
    and carries each scenario's rates; a default page leaves it out, and a folder without scores is refused."""
    rows = {"rec_a": score_case({"effects": {}}, {"verdict": "none", "accepted": [], "ambiguous_with": {},
                                                   "ranked": [], "rules_fired": []}),
            "rec_b": score_case({"effects": {"duffing": {"k3_rel": -0.002}}, "strength": {"duffing": "clear"}},
                                {"verdict": "explained", "accepted": ["duffing"], "ambiguous_with": {},
                                 "ranked": [{"effect": "duffing", "shrink": 0.7}], "rules_fired": [],
                                 "detection_limits": {"effects": {"duffing": {"params": {"k3_rel": 0.001}}}}})}
    res = {"folder": "/somewhere/records", "shrink_floor": 0.2,
           "scenarios": {"nominal_a": {"rows": rows, "summary": summary(rows)}}}
    (tmp_path / "scores.json").write_text(json.dumps(res))
    out = tmp_path / "v.md"
    assert page.main(["--only", "diagnosis", "--diagnosis-results", str(tmp_path), "-o", str(out)]) == 0
    md = out.read_text()
    assert "| 2 | duffing (clear) | explained | duffing (0.70) | 2 | yes |" in md
    assert "| nominal_a | 1 / 1 | 1 / 1 | 1 / 1 | 1 / 1 | 0 / 0 | 0 | 0 |" in md
    assert "rec_a" not in md and "rec_b" not in md
    assert "diagnosis" in page.OPT_IN
    assert page.main(["--diagnosis-results", str(tmp_path / "nothing"), "-o", str(out)]) == 2


def test_the_benchmark_scores_join_the_diagnosis_section(tmp_path):
    """A finished benchmark folder adds its targets table (measured, counts, Wilson interval, target) to the
    diagnosis section; without the independent records' folder it is refused."""
    rows = {"rec_a": score_case({"effects": {}}, {"verdict": "none", "accepted": [], "ambiguous_with": {},
                                                   "ranked": [], "rules_fired": []})}
    (tmp_path / "scores.json").write_text(json.dumps({"folder": "/x/records", "shrink_floor": 0.2,
                                                      "scenarios": {"nominal_a": {"rows": rows,
                                                                                  "summary": summary(rows)}}}))
    bench = tmp_path / "bench"
    bench.mkdir()
    (bench / "scores.json").write_text(json.dumps({
        "cases": 20, "seed": 11, "null_runs": 6, "errors": 0, "false_alarm_rate": 0.5, "null_cases": 2, "top1": 0.7, "top2": 0.8,
        "single_above": 10, "pairs_exact": 1 / 3, "pair_cases": 3, "median_shrink": 0.99,
        "ci95": {"top1": [0.397, 0.892]}}))
    nulls = tmp_path / "nulls"
    nulls.mkdir()
    (nulls / "scores.json").write_text(json.dumps({
        "cases": 12, "seed": 12, "null_runs": 6, "errors": 0, "false_alarm_rate": 1 / 12, "null_cases": 12,
        "top1": None, "top2": None, "single_above": 0, "pairs_exact": None, "pair_cases": 0, "median_shrink": None,
        "mix": {"p_null": 1.0, "p_single": 0.0}}))
    out = tmp_path / "v.md"
    assert page.main(["--only", "diagnosis", "--diagnosis-results", str(tmp_path), "--benchmark-results", str(bench),
                      "--benchmark-results", str(nulls), "-o", str(out)]) == 0
    md = out.read_text()
    assert "20 cases of seed 11, 6 null re-simulations per diagnosis, 0 errors" in md
    assert "| top-1, single effects above the limit | 0.700 | 7 of 10 | 0.397-0.892 |" in md
    assert "| false alarms (null cases) | 0.500 | 1 of 2 |" in md
    # a second run, of null units only, adds its own table after the first
    assert md.index("--seed S --mix null") > md.index("1 of 2") and "| false alarms (null cases) | 0.083 | 1 of 12 |" in md
    assert page.main(["--only", "diagnosis", "--benchmark-results", str(bench), "-o", str(out)]) == 2


@pytest.mark.parametrize("text", ["{not json", "[1, 2]", '{"rows": []}'])
def test_a_malformed_results_folder_is_refused_naming_its_file(tmp_path, capsys, text):
    (tmp_path / "scores.json").write_text(text)
    assert page.main(["--only", "diagnosis", "--diagnosis-results", str(tmp_path), "-o", str(tmp_path / "v.md")]) == 2
    assert str(tmp_path / "scores.json") in capsys.readouterr().err
    assert not (tmp_path / "v.md").exists()
