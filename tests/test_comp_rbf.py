"""RBF network: fits a known function; embedding; scikit-learn contract."""

import numpy as np
from sklearn.base import clone

from fmvmg_sim.compensation.rbf import RBFNetwork, delay_embed


def test_fits_sinc_to_stated_rms():
    rng = np.random.default_rng(0)
    X = rng.uniform(-10, 10, (4000, 1))
    y = np.sinc(X[:, 0] / np.pi)  # sin(x)/x
    net = RBFNetwork(n_centers=40, sigma=0.6, alpha=1e-9).fit(X, y)
    Xt = np.linspace(-9.5, 9.5, 500)[:, None]
    rms = np.sqrt(np.mean((net.predict(Xt) - np.sinc(Xt[:, 0] / np.pi)) ** 2))
    assert rms < 5e-3


def test_default_sigma_and_noisy_fit_beats_the_noise():
    rng = np.random.default_rng(1)
    X = rng.uniform(-3, 3, (5000, 2))
    f = np.exp(-(X**2).sum(1)) + 0.3 * X[:, 0]
    yn = f + 0.1 * rng.standard_normal(len(f))
    default = RBFNetwork(n_centers=30).fit(X, yn)
    assert 0.3 < default.sigma_ < 3.0
    assert np.sqrt(np.mean((default.predict(X) - f) ** 2)) < 0.07  # under the 0.1 noise
    tuned = RBFNetwork(n_centers=30, sigma=1.0).fit(X, yn)
    assert np.sqrt(np.mean((tuned.predict(X) - f) ** 2)) < 0.055


def test_delay_embedding_leaves_the_sample_out():
    x = np.arange(10.0)
    X, y = delay_embed(x, d=2)
    assert X.shape == (10, 4) and np.array_equal(y, x)
    assert X[5].tolist() == [3.0, 4.0, 6.0, 7.0]
    Xc, _ = delay_embed(x, d=3, symmetric=False)
    assert Xc.shape == (10, 3) and Xc[5].tolist() == [2.0, 3.0, 4.0]


def test_estimator_contract():
    net = RBFNetwork(n_centers=7, sigma=2.0, alpha=1e-3)
    assert clone(net).get_params()["n_centers"] == 7
    X = np.random.default_rng(2).normal(size=(200, 3))
    assert net.fit(X, X[:, 0]).score(X, X[:, 0]) > 0.85
