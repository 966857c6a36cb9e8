"""Detection limits (fmvmg_sim.diagnosis.detection): the power model, and the limit against the diagnosis itself."""

import numpy as np
import pytest

from fmvmg_sim.validation.scoring import detection_claim, size_ratio
from fmvmg_sim.diagnosis.detection import POWER, pass_rate
from fmvmg_sim.diagnosis.pipeline import diagnose
from fmvmg_sim.diagnosis.report import detection_lines
from fmvmg_sim.effects import MODELS
from fmvmg_sim.record import read_record, write_record
from tests.test_diagnosis_helpers import NOMINAL, oven_record

THETA = {"q_sense_rel": 0.1, "quadrature_rel": -0.08, "demod_phase_mrad": 1.0, "f_modes_rel": 0.002,
         "q_drive_rel": -0.1}


def _pw(a, folds=((20.0, 1e6), (20.0, 1e6), (20.0, 1e6)), need=2, F=400.0, nats_train=30.0):
    """A linear signature of amplitude ``a``: (nats per unit a^2, training information) per fold."""
    return pass_rate(a * np.sqrt(F), nats_train * a * a, 1, 4000, [(i * a * a, i / F_k) for i, F_k in folds], need)


def test_power_rises_from_zero_to_one_with_the_amplitude():
    a = np.geomspace(1e-3, 1e2, 60)
    p = np.array([_pw(x) for x in a])
    assert p[0] < 1e-6 and p[-1] > 1 - 1e-9
    assert np.all(np.diff(p) >= -1e-12)


def test_the_fold_rule_is_the_attributions():
    # two passing folds needed, but only one fold can test the effect: it carries it alone (Scorer.folds_ok)
    assert _pw(100.0, folds=((20.0, 1e6), (0.0, 1e6), (0.0, 1e6))) == pytest.approx(1.0)
    # no held-out fold sees it: however strong on the training window, it cannot pass
    assert _pw(100.0, folds=((0.0, 1e6),) * 3) == 0.0
    # the refit's estimation error: a fold whose training window barely determines the amplitude (F_k = 1) loses
    # i_k / F_k of what it would gain, and more amplitude is needed to pass it
    a_sharp = next(x for x in np.geomspace(0.01, 10, 400) if _pw(x) >= POWER)
    a_blunt = next(x for x in np.geomspace(0.01, 10, 400) if _pw(x, folds=((20.0, 1.0),) * 3) >= POWER)
    assert a_blunt > 1.2 * a_sharp


def test_fold_criterion_alone_matches_its_gaussian_pass_rate():
    """With the other criteria out of the way, one fold's pass probability is that of its total, N(I, 2 I) with
    I = i a^2, exceeding max(3, 1.96 sqrt(2 I)): checked against a direct simulation of the fold's gain, the sum
    of block NLL differences of a baseline and the true model on whitened residuals."""
    rng = np.random.default_rng(0)
    n, a = 200, 1.0
    u = rng.standard_normal(n) * np.sqrt(2 * 12.0 / n)   # i = 1/2 sum u^2 = 12 nats at a = 1
    i = 0.5 * float(u @ u)
    e = rng.standard_normal((20000, n))
    tot = 0.5 * (((a * u + e) ** 2) - e ** 2).sum(axis=1)   # baseline minus truth NLL, summed over the fold
    sim = np.mean(tot > max(3.0, 1.96 * np.sqrt(2 * i * a * a)))
    p = pass_rate(None, 1e9, 1, 4000, [(i * a * a, 0.0)], 1)
    assert p == pytest.approx(sim, abs=0.02)


def test_size_ratio_reads_the_reports_limits():
    lim = {"power": 0.9, "effects": {"reference_drift": {"params": {"vref_tc_per_K": 1e-8, "rectifier_mV_per_K": 1e-4}},
                                     "duffing": {"params": {"k3_rel": None}}}}
    truth = {"vref_tc_per_K": -3e-8, "rectifier_mV_per_K": 5e-5}
    assert size_ratio("reference_drift", truth, lim) == pytest.approx(3.0)
    assert size_ratio("duffing", {"k3_rel": 1e-4}, lim) == 0.0          # no limit within reach: not detectable
    assert size_ratio("flicker_noise", {"h_output_dps2": 1e-5}, lim) is None
    rows = [{"truth": ["duffing"], "mde_ratio": r, "mde_power": 0.9, "in_set": f, "top2": f}
            for r, f in ((2.0, True), (3.0, True), (0.5, False), (0.2, True))]
    dc = detection_claim(rows)
    assert dc["power"] == 0.9 and dc["above"]["cases"] == 2 and dc["above"]["found"] == 2
    assert dc["below"]["cases"] == 2 and dc["below"]["found"] == 1


@pytest.fixture(scope="module")
def phase_limit(tmp_path_factory):
    """The demodulation-phase drift's limit on a null oven record."""
    tmp = tmp_path_factory.mktemp("mde")
    rec, _ = oven_record(tmp, "null", seed=13, theta=THETA)
    rep = diagnose(rec, NOMINAL, n_null=2, progress=False, log=lambda m: None)
    assert rep["accepted"] == []
    return rep["detection_limits"], tmp


def test_the_limit_is_given_for_every_deterministic_effect(phase_limit):
    lim, _ = phase_limit
    assert lim["power"] == POWER
    for name, d in lim["effects"].items():
        assert "error" not in d and d["params"], name
        assert all(v is None or v > 0 for v in d["params"].values()), (name, d)
    text = "\n".join(detection_lines(lim, []))
    assert "Nothing was attributed" in text and "kappa_urad_per_K" in text
    assert ("at the unit's tolerance bound" in text) == bool(lim["knobs_at_bound"])
    flagged = "\n".join(detection_lines(dict(lim, knobs_at_bound=["demod_phase_mrad"]), []))
    assert "The calibration holds demod_phase_mrad at the unit's tolerance bound" in flagged


@pytest.mark.parametrize("times, found", [
    pytest.param(3.0, True, marks=pytest.mark.xfail(strict=True, reason=(
        "under the device's new amplifier-bandwidth TC the record with the effect reads a limit 1.75x the null's; "
        "the limits are redone with the calibration's rework"))),
    (0.25, False)])
def test_an_effect_above_its_limit_is_attributed_and_one_well_below_is_not(phase_limit, times, found):
    """The same design and noise seed as the null: a demodulation-phase drift three times its limit is attributed
    (or named in the ambiguity set), a quarter of it is not; and the limit is the record's design, so the
    report of the record with the effect gives the same one (to the noise of its null's noise model)."""
    lim, tmp = phase_limit
    k0 = lim["effects"]["demod_phase_drift"]["params"]["kappa_urad_per_K"]
    assert 10.0 < k0 < 1000.0       # the prior range is 20-200 urad/K: a limit inside the plausible sizes
    rec, _ = oven_record(tmp, f"phase{times:g}", {"demod_phase_drift": {"kappa_urad_per_K": times * k0}},
                         seed=13, theta=THETA)
    rep = diagnose(rec, NOMINAL, n_null=2, progress=False, log=lambda m: None)
    named = set(rep["accepted"]) | {x for v in rep["ambiguous_with"].values() for x in v}
    assert ("demod_phase_drift" in named) is found, (rep["verdict"], rep["accepted"], rep["ambiguous_with"])
    k1 = rep["detection_limits"]["effects"]["demod_phase_drift"]["params"]["kappa_urad_per_K"]
    assert k1 == pytest.approx(k0, rel=0.25)


def test_without_the_auxiliary_channels_the_limits_rise(phase_limit):
    """The limit is the record's design: the same record with only the rate output (no quadrature, drive amplitude,
    AGC effort or drive frequency) loses the drive frequency, the die's own thermometer, and the AGC effort, where a Q
    drift shows. A lag must then be long enough to show in the rate output, and the report says which limits lie
    beyond their physical bounds."""
    lim, tmp = phase_limit
    r = read_record(tmp / "null.csv")
    keep = {k: v for k, v in r.columns.items() if k in ("time_s", "temperature_C", "rate_dps", "rate_V")}
    write_record(tmp / "rate_only.csv", type(r)(keep, r.metadata))
    rep = diagnose(tmp / "rate_only.csv", NOMINAL, n_null=2, progress=False, log=lambda m: None)
    assert rep["record"]["channels"] == ["rate_V"]
    bare = rep["detection_limits"]["effects"]
    full = lim["effects"]
    assert bare["thermal_lag"]["params"]["tau_s"] > 100 * full["thermal_lag"]["params"]["tau_s"]
    assert bare["q_factor_drift"]["params"]["q_tc_per_K"] > 100 * full["q_factor_drift"]["params"]["q_tc_per_K"]
    for name, d in bare.items():
        for p, v in d["params"].items():
            bound = max(abs(MODELS[name][p].lo), abs(MODELS[name][p].hi))
            assert (p in d["beyond_bound"]) == (v is None or v > bound), (name, p, v)
    assert any(d["beyond_bound"] for d in bare.values())
