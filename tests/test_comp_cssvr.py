"""CS-SVR (fmvmg_sim.compensation.cssvr): features, decimation, SVR settings, searches."""

import numpy as np
import pytest

from fmvmg_sim.compensation.cssvr import (
    CSSVR, block_average, compare_searches, cv_rmse, make_svr, temperature_features,
)

SMALL = dict(n_max=150, log10_C_bounds=(-1.0, 2.0), n_nests=6)  # keep the suite fast


def drift_of(X):
    """A nonlinear drift in deg/s of T (degC) and dT/dt (degC/min)."""
    return 0.01 * np.sin((X[:, 0] - 25.0) / 8.0) + 0.004 * X[:, 1]


def run(profile, seed, n=3000):
    t_s = np.arange(n) * 2.0
    if profile == "heating":
        T = 25.0 + 30.0 * (1.0 - np.exp(-t_s / 1500.0))
    else:
        T = 55.0 - 30.0 * (1.0 - np.exp(-t_s / 1200.0))
    X = temperature_features(t_s, T, smooth_s=0.0)
    y = drift_of(X) + 0.002 * np.random.default_rng(seed).standard_normal(n)
    return X, y


def test_temperature_features_on_a_ramp():
    t_s = np.arange(0.0, 600.0, 0.5)
    T = 20.0 + t_s / 60.0 + 0.01 * np.random.default_rng(0).standard_normal(t_s.size)
    X = temperature_features(t_s, T, smooth_s=60.0)
    np.testing.assert_array_equal(X[:, 0], T)
    # 1 degC/min; the 60 s moving average keeps the slope and removes most sensor noise
    np.testing.assert_allclose(np.median(X[200:-200, 1]), 1.0, atol=0.01)
    assert np.std(X[200:-200, 1]) < 0.05


def test_block_average():
    a = np.arange(10.0)
    (b,) = block_average(4, a)
    np.testing.assert_array_equal(b, [1.0, 4.0, 7.0])  # blocks of 3, partial last block dropped
    X, y = block_average(2000, np.ones((50, 2)), np.arange(50.0))
    assert X.shape == (50, 2) and y[-1] == 49.0


def test_svr_parameterisation():
    m = make_svr(1.0, np.log10(0.5), epsilon=0.02)
    assert m.C == pytest.approx(10.0) and m.gamma == pytest.approx(1.0 / (2 * 0.25)) and m.epsilon == 0.02
    assert m.kernel == "rbf"


def test_cssvr_learns_drift_held_out_heating_but_not_cooling():
    Xtr, ytr = run("heating", 1)
    model = CSSVR(budget=18, seed=0, **SMALL).fit(Xtr, ytr)
    assert model.search_result_.nfev == 18
    assert model.epsilon_ == pytest.approx(0.05 * np.std(block_average(150, ytr)[0]))
    assert 10 ** -1 <= model.C_ <= 10 ** 2 and 10 ** -2 <= model.sigma_ <= 10
    rmse = lambda X: float(np.sqrt(np.mean((model.predict(X) - drift_of(X)) ** 2)))  # noqa: E731
    fit_rmse = rmse(Xtr)
    assert fit_rmse < 0.15 * np.std(drift_of(Xtr))
    # another heating run (new noise) lies inside the training inputs: the model carries over
    Xh, _ = run("heating", 2)
    assert rmse(Xh) < 0.15 * np.std(drift_of(Xh))
    # a cooling run has dT/dt < 0, never seen in training: the RBF model cannot extrapolate
    Xc, _ = run("cooling", 3)
    assert rmse(Xc) > 5 * fit_rmse


def test_cv_objective_prefers_sensible_parameters():
    X, y = run("heating", 3)
    Xd, yd = block_average(150, X, y)
    Xs = (Xd - Xd.mean(0)) / Xd.std(0)
    eps = 0.05 * np.std(yd)
    good = cv_rmse([1.0, 0.0], Xs, yd, eps)
    tiny_sigma = cv_rmse([1.0, -2.0], Xs, yd, eps)  # sigma = 0.01: memorises, cannot extrapolate
    assert good < 0.5 * tiny_sigma


def test_compare_searches_same_budget():
    X, y = run("heating", 4)
    out = compare_searches(X, y, budget=12, seed=1, **SMALL)
    assert set(out) == {"cuckoo", "grid", "de"}
    for m in out.values():
        assert m.search_result_.nfev <= 12 and np.isfinite(m.cv_rmse_)
    best = min(m.cv_rmse_ for m in out.values())
    assert all(m.cv_rmse_ < 3 * best for m in out.values())


def test_unknown_search():
    X, y = run("heating", 5, n=200)
    with pytest.raises(ValueError):
        CSSVR(search="random", **SMALL).fit(X, y)
