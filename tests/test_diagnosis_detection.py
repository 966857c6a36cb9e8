"""Detection limits (fmvmg_sim.diagnosis.detection): the power model, and the limit against the diagnosis itself."""

import numpy as np
import pytest

from fmvmg_sim.validation.scoring import detection_claim, size_ratio
from fmvmg_sim.diagnosis.detection import POWER, pass_rate


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
