"""CS-SVR: an RBF support-vector regression of drift on temperature, tuned by cuckoo search.

Paper 004 section 3.4 with the settings of compensation.md section 5:
``SVR(kernel='rbf', C, gamma=1/(2 sigma^2), epsilon=0.05 std(y), max_iter=1e5)`` on
standardised inputs ``[T, dT/dt]``, at most ``n_max`` = 2000 block-averaged points. ``C``
and ``sigma`` are searched in ``log10 C in [-1, 3]``, ``log10 sigma in [-2, 1]`` by
minimising the mean RMSE of a 5-fold ``TimeSeriesSplit`` on the training data only (each
fold is fitted on the past and scored on the following block). The same objective can be
minimised by a grid or by differential evolution at the same evaluation budget
(:func:`compare_searches`), the baselines the paper does not report.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.model_selection import TimeSeriesSplit
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVR
from sklearn.utils.validation import check_is_fitted
from tqdm import tqdm

from .cuckoo import SearchResult, cuckoo_search, de_search, grid_search
from .selection import tangent_continuation


def temperature_features(time_s, temperature_C, smooth_s: float = 60.0) -> np.ndarray:
    """The regressors ``[T in degC, dT/dt in degC/min]``, one row per sample.

    Parameters
    ----------
    time_s : array_like
        Time base in s (may be uneven).
    temperature_C : array_like
        Measured temperature in degC.
    smooth_s : float, optional
        Width of the centred moving average applied before differentiating (the sensor's
        white noise would otherwise dominate dT/dt).

    Returns
    -------
    ndarray, shape (n, 2)
    """
    t = np.asarray(time_s, dtype=float)
    T = np.asarray(temperature_C, dtype=float)
    dt_s = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    w = max(int(round(smooth_s / dt_s)), 1)
    if w > 1 and T.size > w:
        pad = np.pad(T, (w // 2, w - 1 - w // 2), mode="edge")
        T_s = np.convolve(pad, np.ones(w) / w, mode="valid")
    else:
        T_s = T
    dTdt = np.gradient(T_s, t) * 60.0 if t.size > 1 else np.zeros_like(T)
    return np.column_stack([T, dTdt])


def block_average(n_max: int, *arrays):
    """Average consecutive blocks so that at most ``n_max`` rows remain.

    Parameters
    ----------
    n_max : int
        Maximum number of rows kept.
    *arrays : ndarray
        Arrays with the same first dimension.

    Returns
    -------
    list of ndarray
        Block means (a trailing partial block is dropped when blocks are longer than 1).
    """
    n = len(arrays[0])
    m = max(int(math.ceil(n / n_max)), 1)
    if m == 1:
        return [np.asarray(a, dtype=float) for a in arrays]
    k = n // m
    return [np.asarray(a, dtype=float)[:k * m].reshape((k, m) + np.shape(a)[1:]).mean(axis=1) for a in arrays]


def make_svr(log10_C: float, log10_sigma: float, epsilon: float, max_iter: int = 100_000) -> SVR:
    """The paper's SVR for one parameter pair.

    Parameters
    ----------
    log10_C, log10_sigma : float
        Regularisation and RBF width (in standardised input units), as base-10 logs.
    epsilon : float
        Insensitive-zone half width, in target units.
    max_iter : int, optional
        libsvm iteration cap (bounds the cost of large C).

    Returns
    -------
    sklearn.svm.SVR
    """
    sigma = 10.0 ** log10_sigma
    return SVR(kernel="rbf", C=10.0 ** log10_C, gamma=1.0 / (2.0 * sigma ** 2), epsilon=epsilon,
               max_iter=max_iter)


def cv_rmse(params, X: np.ndarray, y: np.ndarray, epsilon: float, n_splits: int = 5) -> float:
    """Mean RMSE over a ``TimeSeriesSplit`` (fit on each past block, score on the next).

    Parameters
    ----------
    params : array_like, shape (2,)
        ``[log10 C, log10 sigma]``.
    X : ndarray, shape (n, d)
        Standardised inputs in time order.
    y : ndarray, shape (n,)
        Target.
    epsilon : float
        SVR epsilon.
    n_splits : int, optional
        Number of folds.

    Returns
    -------
    float
    """
    errs = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        for tr, te in TimeSeriesSplit(n_splits=n_splits).split(X):
            model = make_svr(params[0], params[1], epsilon).fit(X[tr], y[tr])
            errs.append(float(np.sqrt(np.mean((model.predict(X[te]) - y[te]) ** 2))))
    return float(np.mean(errs))


class CSSVR(BaseEstimator, RegressorMixin):
    """RBF SVR whose ``C`` and ``sigma`` are chosen by a search on time-series CV RMSE.

    Parameters
    ----------
    search : {"cuckoo", "grid", "de"}, optional
        Search method (cuckoo search is the paper's).
    budget : int, optional
        Objective evaluations (each is ``n_splits`` SVR fits); default 15 nests x 50 generations.
    n_nests : int, optional
        Cuckoo-search nests.
    n_splits : int, optional
        ``TimeSeriesSplit`` folds.
    n_max : int, optional
        Training points kept after block averaging.
    log10_C_bounds, log10_sigma_bounds : tuple of float, optional
        Search box.
    epsilon_frac : float, optional
        ``epsilon = epsilon_frac * std(y)``.
    seed : int, optional
        Search seed.
    progress : bool, optional
        Show a tqdm bar of objective evaluations on stderr.
    """

    def __init__(self, search: str = "cuckoo", budget: int = 1515, n_nests: int = 15, n_splits: int = 5,
                 n_max: int = 2000, log10_C_bounds=(-1.0, 3.0), log10_sigma_bounds=(-2.0, 1.0),
                 epsilon_frac: float = 0.05, seed: int = 0, progress: bool = False):
        self.search = search
        self.budget = budget
        self.n_nests = n_nests
        self.n_splits = n_splits
        self.n_max = n_max
        self.log10_C_bounds = log10_C_bounds
        self.log10_sigma_bounds = log10_sigma_bounds
        self.epsilon_frac = epsilon_frac
        self.seed = seed
        self.progress = progress

    def _prepare(self, X, y):
        Xd, yd = block_average(self.n_max, np.asarray(X, dtype=float), np.asarray(y, dtype=float))
        self.scaler_ = StandardScaler().fit(Xd)
        self.epsilon_ = self.epsilon_frac * float(np.std(yd))
        self.n_points_ = len(yd)
        return self.scaler_.transform(Xd), yd

    def fit(self, X, y) -> "CSSVR":
        """Search ``C`` and ``sigma`` on the training data, then refit on all of it.

        Parameters
        ----------
        X : array_like, shape (n, d)
            Inputs in time order, e.g. :func:`temperature_features`.
        y : array_like, shape (n,)
            Drift to model.

        Returns
        -------
        CSSVR
            ``self``, with ``C_``, ``sigma_``, ``cv_rmse_``, ``search_result_``, ``n_points_``
            (training points after block averaging), ``svr_`` and the input box ``lo_``/``hi_``.
        """
        if self.search not in ("cuckoo", "grid", "de"):
            raise ValueError(f"search must be 'cuckoo', 'grid' or 'de', got {self.search!r}")
        Xs, ys = self._prepare(X, y)
        self.lo_, self.hi_ = np.min(X, axis=0), np.max(X, axis=0)
        bounds = [self.log10_C_bounds, self.log10_sigma_bounds]
        bar = tqdm(total=self.budget, desc=f"CS-SVR {self.search} search", disable=not self.progress, leave=False)

        def fun(p):
            bar.update(1)
            return cv_rmse(p, Xs, ys, self.epsilon_, self.n_splits)

        if self.search == "cuckoo":
            res = cuckoo_search(fun, bounds, budget=self.budget, n_nests=self.n_nests, seed=self.seed)
        elif self.search == "grid":
            res = grid_search(fun, bounds, self.budget)
        else:
            res = de_search(fun, bounds, self.budget, seed=self.seed)
        bar.close()
        self.search_result_: SearchResult = res
        self.C_, self.sigma_ = 10.0 ** res.x[0], 10.0 ** res.x[1]
        self.cv_rmse_ = res.fun
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            self.svr_ = make_svr(res.x[0], res.x[1], self.epsilon_).fit(Xs, ys)
        return self

    def predict(self, X) -> np.ndarray:
        """Predicted drift; beyond the training inputs' box, continued along the tangent plane.

        An RBF SVR far outside its data returns its intercept, and near the edge the tail of
        its kernels: neither is a forecast. :func:`.selection.tangent_continuation` extends it
        linearly from the edge instead.

        Parameters
        ----------
        X : array_like, shape (n, d)
            Inputs (same columns as in :meth:`fit`).

        Returns
        -------
        ndarray, shape (n,)
        """
        check_is_fitted(self, "svr_")
        return tangent_continuation(lambda Z: self.svr_.predict(self.scaler_.transform(Z)),
                                    np.asarray(X, dtype=float), self.lo_, self.hi_)


def compare_searches(X, y, budget: int, seed: int = 0, **kw) -> dict[str, CSSVR]:
    """Fit :class:`CSSVR` with cuckoo, grid and DE searches at the same budget.

    Parameters
    ----------
    X, y : array_like
        Training data (see :meth:`CSSVR.fit`).
    budget : int
        Evaluations allowed to each search.
    seed : int, optional
        Search seed.
    **kw
        Other :class:`CSSVR` parameters.

    Returns
    -------
    dict
        ``{"cuckoo": CSSVR, "grid": CSSVR, "de": CSSVR}``, fitted; compare ``cv_rmse_``
        and ``search_result_.nfev``.
    """
    return {m: CSSVR(search=m, budget=budget, seed=seed, **kw).fit(X, y) for m in ("cuckoo", "grid", "de")}
