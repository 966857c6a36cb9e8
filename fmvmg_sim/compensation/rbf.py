"""Gaussian RBF network as a scikit-learn regressor, and the time-delay embedding it denoises with.

Hidden layer: ``n_centers`` Gaussian units exp(-|x - c_j|^2 / (2 sigma^2)) with KMeans
centres (fitted on at most ``max_kmeans_samples`` rows) and one shared spread ``sigma``.
Output layer: ridge regression (penalty ``alpha`` per sample, so it does not depend on the
number of rows) with an unpenalised intercept. Prediction runs in chunks so millions of
rows never build one big design matrix. (compensation.md section 5.)
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.cluster import KMeans
from sklearn.utils.validation import check_is_fitted, validate_data

_CHUNK_ROWS = 100_000


def delay_embed(x: np.ndarray, d: int = 4, symmetric: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Time-delay embedding of ``x`` with targets ``x[k]``, same length as ``x``.

    Parameters
    ----------
    x : ndarray
        Signal (standardise it first).
    d : int
        Delay depth (compensation.md: 4, allowed 2-8).
    symmetric : bool
        Offline form ``[x[k-d..k-1], x[k+1..k+d]]`` (the sample itself is left out, so the
        network must predict it from its neighbours); else causal ``[x[k-1..k-d]]``.

    Returns
    -------
    X : ndarray, shape (len(x), 2d or d)
        Inputs; edges use the reflected signal.
    y : ndarray
        Targets, ``x`` itself.
    """
    x = np.asarray(x, float)
    xp = np.pad(x, d, mode="reflect")
    n = len(x)
    lags = list(range(-d, 0)) + (list(range(1, d + 1)) if symmetric else [])
    X = np.empty((n, len(lags)))
    for c, lag in enumerate(lags):
        X[:, c] = xp[d + lag: d + lag + n]
    return X, x


def gaussian_design(X: np.ndarray, centers: np.ndarray, sigma: float) -> np.ndarray:
    """Hidden-layer outputs exp(-|x - c|^2 / (2 sigma^2)).

    Parameters
    ----------
    X : ndarray, shape (n, p)
        Inputs.
    centers : ndarray, shape (M, p)
        Centres.
    sigma : float
        Shared spread.

    Returns
    -------
    ndarray, shape (n, M)
    """
    d2 = (X * X).sum(1)[:, None] - 2.0 * X @ centers.T + (centers * centers).sum(1)[None, :]
    return np.exp(-np.maximum(d2, 0.0) / (2.0 * sigma * sigma))


def ridge_weights(Phi: np.ndarray, y: np.ndarray, alpha: float) -> tuple[np.ndarray, float]:
    """Ridge solution with an unpenalised intercept and a per-sample penalty ``alpha``.

    Parameters
    ----------
    Phi : ndarray, shape (n, M)
        Design matrix.
    y : ndarray, shape (n,)
        Targets.
    alpha : float
        Penalty per sample: minimises mean((y - Phi w - b)^2) + alpha |w|^2.

    Returns
    -------
    w : ndarray, shape (M,)
    b : float
    """
    mu, ym = Phi.mean(0), y.mean()
    Pc = Phi - mu
    G = Pc.T @ Pc / len(y) + alpha * np.eye(Phi.shape[1])
    w = np.linalg.solve(G, Pc.T @ (y - ym) / len(y))
    return w, float(ym - mu @ w)


class RBFNetwork(RegressorMixin, BaseEstimator):
    """Gaussian RBF network: KMeans centres, one shared spread, ridge output weights.

    Parameters
    ----------
    n_centers : int
        Number of hidden units M.
    sigma : float, optional
        Shared Gaussian spread in input units; default d_max / sqrt(2 M) (d_max the largest
        distance between centres).
    alpha : float
        Ridge penalty per sample.
    max_kmeans_samples : int
        KMeans runs on a random subsample of at most this many rows.
    random_state : int
        Seed of the subsample and KMeans.
    """

    def __init__(self, n_centers: int = 20, sigma: float | None = None, alpha: float = 1e-6,
                 max_kmeans_samples: int = 20000, random_state: int = 0):
        self.n_centers = n_centers
        self.sigma = sigma
        self.alpha = alpha
        self.max_kmeans_samples = max_kmeans_samples
        self.random_state = random_state

    def fit(self, X, y, centers: np.ndarray | None = None) -> "RBFNetwork":
        """Place centres (unless given) and solve the output weights.

        Parameters
        ----------
        X : array-like, shape (n, p)
            Inputs.
        y : array-like, shape (n,)
            Targets.
        centers : ndarray, optional
            Precomputed centres (e.g. cached across hyper-parameter searches).

        Returns
        -------
        RBFNetwork
            ``self``.
        """
        X, y = validate_data(self, X, y, y_numeric=True)
        self.centers_ = self.kmeans_centers(X) if centers is None else np.asarray(centers, float)
        if self.sigma is None:
            c = self.centers_
            dmax = np.sqrt(((c[:, None, :] - c[None, :, :]) ** 2).sum(-1).max()) if len(c) > 1 else 1.0
            self.sigma_ = float(dmax / np.sqrt(2.0 * len(c))) or 1.0
        else:
            self.sigma_ = float(self.sigma)
        self.coef_, self.intercept_ = ridge_weights(gaussian_design(X, self.centers_, self.sigma_), y, self.alpha)
        return self

    def kmeans_centers(self, X: np.ndarray) -> np.ndarray:
        """KMeans centres of (a subsample of) ``X``.

        Parameters
        ----------
        X : ndarray, shape (n, p)
            Inputs.

        Returns
        -------
        ndarray, shape (n_centers, p)
        """
        rng = np.random.default_rng(self.random_state)
        if len(X) > self.max_kmeans_samples:
            X = X[np.sort(rng.choice(len(X), self.max_kmeans_samples, replace=False))]
        k = min(int(self.n_centers), len(X))
        return KMeans(k, n_init=1, random_state=self.random_state).fit(X).cluster_centers_

    def predict(self, X) -> np.ndarray:
        """Network output, computed in chunks of 1e5 rows.

        Parameters
        ----------
        X : array-like, shape (n, p)
            Inputs.

        Returns
        -------
        ndarray, shape (n,)
        """
        check_is_fitted(self, "coef_")
        X = validate_data(self, X, reset=False)
        out = np.empty(len(X))
        for s in range(0, len(X), _CHUNK_ROWS):
            out[s:s + _CHUNK_ROWS] = gaussian_design(X[s:s + _CHUNK_ROWS], self.centers_, self.sigma_) @ self.coef_
        return out + self.intercept_
