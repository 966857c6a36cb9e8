"""Held-out gap (fmvmg_sim.diagnosis.heldout.Scorer.gaps / shrink): each channel's excess over the null, in units of
the null's mean square, or of one held-out sigma squared where the null's replicates show less."""

from types import SimpleNamespace

import pytest

from fmvmg_sim.diagnosis.heldout import GAP_UNIT_Z2, TOTAL_GAP, Scorer


def _scorer(noise_ms: dict, metrics: dict):
    """A Scorer-like object whose held-out metrics for a prediction ``p`` are ``metrics[p]``."""
    s = SimpleNamespace(noise_ms=noise_ms, metrics=lambda pred: metrics[pred])
    s.gaps = Scorer.gaps.__get__(s)
    s.shrink = Scorer.shrink.__get__(s)
    return s


def test_a_channel_inside_its_model_floor_does_not_outweigh_the_located_gap():
    """The rate channel's gap (null 3.2 sigma^2, record 30 -> 10.8 with the candidate) shrinks by 71 %; the drive
    frequency, whose sigma is a model floor (null 9e-6), misfits by 7e-4 -> 8e-4 sigma^2, two thousandths of one
    sigma: in the null's units that was a gap of 74 -> 89 and the candidate's shrink read -0.07; in sigmas it is
    nothing, and the shrink is the rate channel's."""
    noise = {"z2_rate_V": 3.184, "z2_drive_frequency_Hz": 8.77e-6, "rms_rate_dps": 4e-4}
    s = _scorer(noise, {"before": {"z2_rate_V": 29.94, "z2_drive_frequency_Hz": 6.55e-4, "rms_rate_dps": 3.2e-3},
                        "after": {"z2_rate_V": 10.81, "z2_drive_frequency_Hz": 7.86e-4, "rms_rate_dps": 9e-4}})
    gb = s.gaps("before")[TOTAL_GAP]
    assert gb == pytest.approx((29.94 - 3.184) / 3.184 + (6.55e-4 - 8.77e-6) / GAP_UNIT_Z2)
    assert s.shrink("after", "before") == pytest.approx(1 - ((10.81 - 3.184) / 3.184 + 7.77e-4) / gb)
    assert s.shrink("after", "before") > 0.7
    # the mean squares (deg/s^2) are reported beside it, excess over the null's
    assert s.gaps("before")["rms_rate_dps"] == pytest.approx(2.8e-3)


def test_a_channel_at_or_above_one_sigma_squared_keeps_the_nulls_units():
    """Where the null's replicates show at least one sigma squared, the gap is in their units, as before; a record
    inside its null leaves no gap and no shrink."""
    s = _scorer({"z2_rate_V": 2.0}, {"a": {"z2_rate_V": 6.0}, "b": {"z2_rate_V": 1.5}})
    assert s.gaps("a")[TOTAL_GAP] == pytest.approx(2.0)
    assert s.gaps("b")[TOTAL_GAP] == 0.0
    assert s.shrink("a", "b") is None
