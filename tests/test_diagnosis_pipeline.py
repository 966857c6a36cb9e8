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


def test_look_alikes_rank_right_after_the_verdict_by_gain():
    """Fresh case 90501/33: mode-split drift accepted, its look-alikes phase drift (the truth; the largest held-out
    gain, but not significant alone) and quadrature drift (passed alone). Feedthrough passed alone with a gain below
    the accepted effect's interval, so it is no look-alike. The look-alikes come second and third, by gain."""
    rows = [_row("mode_split_drift", True, 0.083), _row("quadrature_drift", True, 0.064),
            _row("feedthrough", True, 0.036), _row("demod_phase_drift", False, 0.097),
            _row("temperature_rate", False, -0.008)]
    amb = ["demod_phase_drift", "quadrature_drift"]
    out = [r["effect"] for r in rank_rows(rows, ["mode_split_drift"], amb)]
    assert out == ["mode_split_drift", "demod_phase_drift", "quadrature_drift", "feedthrough", "temperature_rate"]
    # without the ambiguity set: passed alone first, so the truth ranks fourth (the ranking before session 42)
    out = [r["effect"] for r in rank_rows(rows, ["mode_split_drift"])]
    assert out == ["mode_split_drift", "quadrature_drift", "feedthrough", "demod_phase_drift", "temperature_rate"]


def test_nothing_accepted_ranks_by_passing_alone_then_gain():
    rows = [_row("a", False, 5.0), _row("b", True, 1.0), _row("c", False, None), _row("d", True, 2.0)]
    assert [r["effect"] for r in rank_rows(rows, [])] == ["d", "b", "a", "c"]


def _cover(*train_C):
    return {"folds": [{"train_C": t} for t in train_C]}


def test_a_record_held_at_one_temperature_cannot_identify_temperature_laws():
    """90006/17: every training window at 31.9 C, the last held-out block ramping; the design, not the
    diagnosis, is why a Q drift plus a quadrature drift of SNR 1403 are not found."""
    from fmvmg_sim.diagnosis.attribute import MIN_TRAIN_SPAN_K, TEMPERATURE_DRIVEN
    from fmvmg_sim.diagnosis.pipeline import design_check
    held = design_check(_cover([31.9, 31.9], [31.9, 31.9], [31.9, 31.9]))
    assert held["temperature_laws_identifiable"] is False and held["train_span_K"] == 0.0
    assert held["not_identifiable"] == list(TEMPERATURE_DRIVEN)
    assert "stress_relaxation" not in held["not_identifiable"]  # acts through time: a hold shows it
    # one fold whose training window spans the limit is enough; a missing window counts as no span
    ramp = design_check(_cover(None, [20.0, 20.0 + MIN_TRAIN_SPAN_K], [20.0, 40.0]))
    assert ramp["temperature_laws_identifiable"] is True and ramp["not_identifiable"] == []
    assert ramp["train_span_K"] == 20.0
    assert design_check(_cover([20.0, 20.0 + 0.99 * MIN_TRAIN_SPAN_K]))["temperature_laws_identifiable"] is False
