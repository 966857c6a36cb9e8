"""The report's ranking of candidates (the end-to-end diagnoses are in test_diagnosis_cases.py)."""

from fmvmg_sim.diagnosis.pipeline import rank_rows


def _row(effect, passed_alone, gain):
    return {"effect": effect, "accepted": passed_alone, "heldout_gain": gain}


def test_a_second_effect_that_did_not_pass_alone_ranks_second():
    """Seed 31415 case 29: the verdict is mode-split plus phase drift, the phase drift failed alone, and two
    look-alikes of the mode-split drift passed alone: the phase drift still ranks second."""
    rows = [_row("temperature_rate", True, 0.29), _row("demod_phase_drift", False, 0.45),
            _row("quadrature_drift", True, 0.36), _row("mode_split_drift", True, 0.38),
            _row("duffing", False, None), _row("feedthrough", False, 0.01)]
    out = [r["effect"] for r in rank_rows(rows, ["mode_split_drift", "demod_phase_drift"])]
    assert out == ["mode_split_drift", "demod_phase_drift", "quadrature_drift", "temperature_rate",
                   "feedthrough", "duffing"]


def test_nothing_accepted_ranks_by_passing_alone_then_gain():
    rows = [_row("a", False, 5.0), _row("b", True, 1.0), _row("c", False, None), _row("d", True, 2.0)]
    assert [r["effect"] for r in rank_rows(rows, [])] == ["d", "b", "a", "c"]
