"""Segments, bins, chained folds, the selection rule and continuation beyond the training range."""

import numpy as np
import pytest

from fmvmg_sim.compensation.segments import describe, make_bins, segment_bounds, slope_within, smooth_within
from fmvmg_sim.compensation.selection import (Candidate, MonomialModel, chained_folds, principal_slope_significance,
                                              select, slope_significance, tangent_continuation, time_blocks)


def gapped_ramp():
    """A 1 K/min ramp sampled at 10 Hz in two stretches, with a 5 K step hidden in the 200 s gap."""
    t1 = np.arange(0, 300, 0.1)
    t2 = np.arange(500, 800, 0.1)
    t = np.r_[t1, t2]
    T = t / 60.0 + np.where(t >= 500, 5.0, 0.0)
    return t, T


def test_bins_and_derivatives_never_straddle_a_gap():
    t, T = gapped_ramp()
    assert segment_bounds(t) == [(0, 3000), (3000, 6000)]
    bins = make_bins(t, 1.0)
    assert len(bins) == 600 and set(np.unique(bins.segment)) == {0, 1}
    Tb = bins.mean(T)
    # a centred 120 s slope: the 5 K step across the gap would add ~2.5 K/min near it if it leaked in
    np.testing.assert_allclose(slope_within(bins, Tb, 120.0) * 60.0, 1.0, rtol=1e-9)
    sm = smooth_within(bins, Tb, 60.0)
    np.testing.assert_allclose(sm[bins.segment == 1].min(), Tb[bins.segment == 1].min() + 0.25, atol=0.02)
    back = bins.to_samples(t, Tb)
    assert np.max(np.abs(back - T)) < 0.01  # interpolation inside each stretch


def test_describe_recognises_bursts():
    t = np.concatenate([k * 305.0 + np.arange(0, 5, 0.02) for k in range(25)])
    d = describe(t)
    assert d["bursty"] and d["segments"] == 25 and d["median_segment_s"] == pytest.approx(5.0)
    assert d["median_gap_s"] == pytest.approx(300.02, abs=0.01)
    assert not describe(np.arange(0, 100, 0.1))["bursty"]


def test_chained_folds_forward_and_backward_and_by_burst():
    t = np.concatenate([k * 300.0 + np.arange(0, 5, 0.1) for k in range(20)])
    bins = make_bins(t, 1.0)
    folds = chained_folds(bins, n_folds=4, min_train_fraction=0.5, by_segment=True)
    assert len(folds) == 8
    starts = set(np.r_[0, np.flatnonzero(np.diff(bins.segment)) + 1])
    for fit, scored in folds:
        assert set(fit).isdisjoint(scored)
        assert scored[0] in starts and (scored[-1] + 1 == len(bins) or scored[-1] + 1 in starts)
    fwd, bwd = folds[:4], folds[4:]
    assert all(fit.max() < scored.min() for fit, scored in fwd)   # fit on the past
    assert all(fit.min() > scored.max() for fit, scored in bwd)   # fit on the future
    assert len(fwd[0][0]) == 50  # half of the 100 bins (10 bursts)


def test_selection_finds_the_true_order_and_reports_every_score():
    rng = np.random.default_rng(1)
    t = np.arange(0, 4000.0)
    T = 20 + 10 * np.sin(2 * np.pi * t / 2000)  # two heating/cooling cycles: every fold interpolates
    y = 0.3 * (T - 20) - 0.05 * (T - 20) ** 2 + rng.normal(0, 0.05, t.size)
    bins = make_bins(t, 1.0)
    X = (bins.mean(T) - 20)[:, None]
    cands = [Candidate(f"order {p}", "T", ["dT"], [(k,) for k in range(1, p + 1)], {"order": p}) for p in range(4)]
    sel = select(cands, {"T": X}, bins.mean(y), bins.counts, chained_folds(bins), bins.t_s, range_vars=X)
    assert sel.chosen.settings["order"] in (2, 3)
    scores = {r["name"]: r["validation_rms"] for r in sel.table}
    assert scores["order 2"] == pytest.approx(0.05, rel=0.1) and scores["order 1"] > 10 * scores["order 2"]
    one_se = select(cands, {"T": X}, bins.mean(y), bins.counts, chained_folds(bins), rule="one-se")
    assert one_se.chosen.settings["order"] == 2  # order 3 adds nothing the data can tell


def test_beyond_the_range_a_slope_only_where_the_blocks_reproduce_it():
    """A drift with a real slope is carried beyond the range along it; a slope of noise is not."""
    t = np.arange(0, 4000.0)
    bins = make_bins(t, 1.0)
    rng = np.random.default_rng(2)
    for T, law, held in ((10 + 20 * t / t[-1], lambda x: 0.2 * x, False),      # 20 K cooling, real slope
                         (20 + 0.1 * rng.standard_normal(t.size), lambda x: 0 * x, True)):  # a soak: noise
        y = law(T - 10) + rng.normal(0, 0.01, t.size)
        X = (bins.mean(T) - 20)[:, None]
        c = Candidate("order 1", "T", ["dT"], [(1,)], {"order": 1})
        sel = select([c], {"T": X}, bins.mean(y), bins.counts, chained_folds(bins), range_vars=X,
                     blocks=time_blocks(bins, 8))
        assert (sel.chosen.settings["held"] == ["dT"]) is held
        sig = sel.chosen.settings["slope_significance"]["dT"]
        assert (sig["t"] >= sig["t_critical"]) is not held
        m = c.model().fit(X, bins.mean(y), bins.counts)
        far = np.array([[40.0]])  # 30 K beyond the cooling's range, 40 K beyond the soak's
        edge = m.predict(np.array([[X.max()]]))[0]
        assert bool(m.predict(far)[0] == pytest.approx(edge)) is held


def test_collinear_thermometers_are_carried_along_their_joint_slope():
    """Two readings of one temperature (a die and a case 0.5 K apart, each with 2 mK of noise): each
    one's own slope is not reproducible from block to block, their joint slope along the data is, and a
    candidate asking for the joint test is continued beyond the range instead of held."""
    rng = np.random.default_rng(5)
    t = np.arange(0, 4000.0)
    bins = make_bins(t, 1.0)
    T = 10 + 20 * t / t[-1]
    die, case = T + 0.002 * rng.standard_normal(t.size), T + 0.5 + 0.002 * rng.standard_normal(t.size)
    y = 0.1 * (die - 10) + 0.1 * (case - 10) + rng.normal(0, 0.05, t.size)
    X = np.column_stack([bins.mean(die) - 20, bins.mean(case) - 20])
    yb, blocks = bins.mean(y), time_blocks(bins, 8)
    each = slope_significance(X, yb, bins.counts, blocks, ["die", "case"])
    joint = principal_slope_significance(X, yb, bins.counts, blocks)
    assert not each["die"]["significant"] and not each["case"]["significant"]
    assert joint["significant"] and joint["t"] > 10 * max(each["die"]["t"], each["case"]["t"])
    assert joint["explained_variance_ratio"] > 0.99 and np.allclose(np.abs(joint["direction"]), 2 ** -0.5, atol=0.01)
    for test, held in ((None, ["die", "case"]), ("joint", [])):
        c = Candidate("die + case", "X", ["die", "case"], [(1, 0), (0, 1)], {"slope_test": test} if test else {})
        sel = select([c], {"X": X}, yb, bins.counts, chained_folds(bins), blocks=blocks)
        assert sorted(sel.chosen.settings["held"]) == sorted(held), each
    m = sel.chosen.model().fit(X, yb, bins.counts)  # the joint test's choice, as it will be used
    # 10 K beyond the range (die 40 C, case 40.5 C): the law itself, 0.1 (40 - 10) + 0.1 (40.5 - 10)
    assert m.predict(np.array([[20.0, 20.5]]))[0] == pytest.approx(0.1 * 30 + 0.1 * 30.5, abs=0.05)


def test_monomial_model_tangent_plane_and_generic_continuation():
    rng = np.random.default_rng(3)
    X = rng.uniform(-1, 1, (500, 2))
    y = 1 + X[:, 0] ** 2 + 2 * X[:, 0] * X[:, 1]
    m = MonomialModel(["a", "b"], [(2, 0), (1, 1)]).fit(X, y)
    assert m.coefficients() == pytest.approx({"1": 1.0, "a^2": 1.0, "a*b": 2.0}, abs=1e-9)
    x = np.array([[3.0, 0.5]])  # a = 3 lies 2 beyond the box; the plane at (1, 0.5): f = 2, df/da = 3
    lo, hi = m.lo_, m.hi_
    edge = np.array([[hi[0], 0.5]])
    f_edge = 1 + edge[0, 0] ** 2 + 2 * edge[0, 0] * 0.5
    expect = f_edge + (2 * edge[0, 0] + 2 * 0.5) * (3.0 - edge[0, 0])
    assert m.predict(x)[0] == pytest.approx(expect, rel=1e-9)
    # the finite-difference version used for models without an analytic gradient agrees
    assert tangent_continuation(m._inside, x, lo, hi)[0] == pytest.approx(expect, rel=1e-3)
    ex = m.extrapolation(x)
    assert ex["terms_extrapolated"] == ["a^2", "a*b"] and ex["variables"]["a"]["above"] == pytest.approx(3 - hi[0])
    m.continuation = "constant"
    assert m.predict(x)[0] == pytest.approx(f_edge, rel=1e-9)
