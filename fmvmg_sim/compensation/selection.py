"""Model selection by forward-chained validation, and drift models that do not extrapolate curvature.

Every compensator with a structure to choose (polynomial order, a dT/dt term, a smoothing
span, a set of auxiliary regressors) chooses it the same way:

1. **Forward-chained folds.** The training record's bins are cut in time: each fold is
   fitted on everything before a cut and scored on the block after it, so every score is a
   forecast, as using the model on a later record is. The cuts lie in the last
   ``1 - min_train_fraction`` of the record (by sample count), and on a record of bursts
   they are moved to the nearest burst boundary (a burst is never split between fitting and
   scoring).
2. **Score.** Each option forecasts each fold's scored block as it will be used (beyond the
   range it was fitted on, it continues from its edge value along the slope of a line fitted
   on that range); the score is the pooled RMS of the scored bins' residuals (bins weighted by
   sample count).
3. **Rule.** The option with the lowest score (``rule="best"``, the default); among equal
   scores the one with fewer coefficients. ``rule="one-se"`` takes instead the simplest
   option whose fold-by-fold mean squared error is within one standard error of the best
   (the "one-standard-error rule"); with the eight folds a record affords that standard
   error is wide, and the rule measurably chose too simple a model on simulated oven runs, so
   it is an option, not the default.
4. **Beyond the range.** Curvature is never extrapolated. Beyond the training range the
   chosen model continues from its value at the range's edge along the slope of a line
   fitted on the whole range, for each variable whose slope is significant: refitted on
   contiguous time blocks of the record, it differs from zero at the :data:`SLOPE_ALPHA`
   level (Student t). Along any other variable it is held constant: a line fitted on a soak's
   0.3 K of sensor noise must not be carried 35 K.

:class:`MonomialModel` is the least-squares model the candidates are made of: an intercept
plus monomials of a few base variables (``dT``, ``dT^2``, ``dT/dt``, ``Q*dT_die``...). Where a
base variable leaves the box it was fitted on, the model is continued from the nearest point
of the box, along its tangent plane or as a constant: a polynomial of any order is at most a
straight line beyond its training range, never a parabola, and
:meth:`MonomialModel.extrapolation` says by how much each variable left the box and which
terms that affected.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree
from scipy.stats import t as student_t

from .segments import Bins


def _monomials(X: np.ndarray, E: np.ndarray) -> np.ndarray:
    """Columns prod_j X[:, j] ** E[k, j], one per row of ``E``."""
    out = np.ones((X.shape[0], E.shape[0]))
    for k, e in enumerate(E):
        for j, p in enumerate(e):
            if p:
                out[:, k] *= X[:, j] ** p
    return out


def _monomial_grad(X: np.ndarray, E: np.ndarray, j: int) -> np.ndarray:
    """d/dX_j of every monomial column."""
    out = np.zeros((X.shape[0], E.shape[0]))
    for k, e in enumerate(E):
        if e[j] == 0:
            continue
        col = e[j] * X[:, j] ** (e[j] - 1)
        for i, p in enumerate(e):
            if i != j and p:
                col = col * X[:, i] ** p
        out[:, k] = col
    return out


def term_name(names: list[str], e) -> str:
    """Readable name of a monomial, e.g. ``dT^2`` or ``Q*dT_die``.

    Parameters
    ----------
    names : list of str
        Base variable names.
    e : sequence of int
        Exponent of each base variable.

    Returns
    -------
    str
    """
    parts = [n if p == 1 else f"{n}^{p}" for n, p in zip(names, e) if p]
    return "*".join(parts) or "1"


@dataclass
class MonomialModel:
    """``y = c0 + sum_k c_k prod_j x_j^e_kj`` by weighted least squares, continued without curvature outside its box.

    Parameters
    ----------
    var_names : list of str
        Names of the base variables (columns of ``X``).
    exponents : list of tuple of int
        One exponent tuple per term (no constant term: the intercept is always there).
    continuation : {"constant", "slope", "tangent"}
        Beyond the box, from the model's value at the nearest point of the box: held there
        (``constant``); along the slopes of a first-order model fitted on the whole box
        (``slope``, the most robustly estimated slope); or along the model's own tangent plane
        there (``tangent``).
    held : tuple of str
        Variables along which the model is held constant beyond the box whatever
        ``continuation`` says (their slope is not significant, :func:`slope_significance`, or
        they are not to be extrapolated at all); the slopes of the others are fitted without them.
    anchor : bool
        Beyond the training range of a non-held variable, take the model's value at the
        training point nearest in the non-held variables, continued from there along their
        slopes (:meth:`off_data`), instead of clamping each variable to its own range. For
        correlated variables (a quadrature that follows the die temperature), whose coefficients
        cancel along the data and are arbitrary across it, a clamped corner of the box is a
        combination the data never fixed.
    """

    var_names: list
    exponents: list
    continuation: str = "tangent"
    held: tuple = ()
    anchor: bool = False
    coef_: np.ndarray | None = field(default=None, repr=False)

    def _E(self) -> np.ndarray:
        return np.asarray(self.exponents, dtype=int).reshape(-1, len(self.var_names))

    @property
    def n_coef(self) -> int:
        """Coefficients including the intercept."""
        return 1 + len(self.exponents)

    @property
    def terms(self) -> list[str]:
        """Term names, intercept first."""
        return ["1"] + [term_name(self.var_names, e) for e in self._E()]

    def fit(self, X: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> "MonomialModel":
        """Weighted least squares on standardised monomial columns.

        Parameters
        ----------
        X : ndarray, shape (n, n_vars)
            Base variables.
        y : ndarray, shape (n,)
            Target.
        w : ndarray, optional
            Row weights (sample counts of bins).

        Returns
        -------
        MonomialModel
            ``self`` with ``coef_`` (intercept, then per standardised column), ``lo_``/``hi_``
            (the box of ``X``), ``mean_``/``scale_`` of the columns.
        """
        X = np.asarray(X, dtype=float).reshape(len(y), -1)
        w = np.ones(len(y)) if w is None else np.asarray(w, dtype=float)
        self.lo_, self.hi_ = X.min(axis=0), X.max(axis=0)
        P = _monomials(X, self._E())
        sw = w / w.sum()
        self.mean_ = sw @ P if P.shape[1] else np.zeros(0)
        sd = np.sqrt(sw @ (P - self.mean_) ** 2) if P.shape[1] else np.zeros(0)
        self.scale_ = np.where(sd > 1e-12 * (np.abs(self.mean_) + 1e-300), sd, np.inf)
        A = np.column_stack([np.ones(len(y)), (P - self.mean_) / self.scale_])
        r = np.sqrt(w)
        self.coef_ = np.linalg.lstsq(A * r[:, None], y * r, rcond=1e-10)[0]
        self.condition_number_ = float(np.linalg.cond(A[:, np.isfinite(np.r_[1.0, self.scale_])] * r[:, None]))
        used = np.array([j for j in np.flatnonzero(self._E().any(axis=0)) if self.var_names[j] not in self.held],
                        dtype=int)
        self.slope_ = np.zeros(X.shape[1])
        if used.size:
            Xu = X[:, used] - sw @ X[:, used]
            self.slope_[used] = np.linalg.lstsq(np.column_stack([np.ones(len(y)), Xu]) * r[:, None], y * r,
                                                rcond=1e-10)[0][1:]
        if self.anchor:
            self._fit_anchor(X)
        return self

    #: Training points kept for the nearest-neighbour anchor (a stride subsample beyond this).
    ANCHOR_MAX_POINTS = 20_000

    def _fit_anchor(self, X: np.ndarray) -> None:
        used = np.flatnonzero(self._E().any(axis=0))
        free = np.array([j for j in used if self.var_names[j] not in self.held], dtype=int)
        self.anchor_free_ = free if free.size else used
        step = max(1, len(X) // self.ANCHOR_MAX_POINTS)
        self.anchor_X_ = X[::step].copy()
        sd = X[:, self.anchor_free_].std(axis=0)
        self.anchor_scale_ = np.where(sd > 0, sd, 1.0)
        self.anchor_tree_ = cKDTree(self.anchor_X_[:, self.anchor_free_] / self.anchor_scale_)

    def off_data(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rows beyond the training range of a variable that is not held, and the training row each is anchored to.

        Such a row is evaluated at the training row nearest to it in the variables that are not
        held (for ``physics``: the die temperature), so the held variables take the values they
        had there instead of a combination never seen in training.

        Parameters
        ----------
        X : ndarray, shape (n, n_vars)

        Returns
        -------
        (ndarray of bool, ndarray of int)
            All False (and zeros) for a model fitted without ``anchor``.
        """
        X = np.asarray(X, dtype=float).reshape(-1, len(self.var_names))
        if not self.anchor:
            return np.zeros(len(X), dtype=bool), np.zeros(len(X), dtype=int)
        F = X[:, self.anchor_free_]
        off = np.any((F < self.lo_[self.anchor_free_]) | (F > self.hi_[self.anchor_free_]), axis=1)
        idx = np.zeros(len(X), dtype=int)
        if off.any():
            idx[off] = self.anchor_tree_.query(F[off] / self.anchor_scale_)[1]
        return off, idx

    def _inside(self, X: np.ndarray) -> np.ndarray:
        P = _monomials(X, self._E())
        return self.coef_[0] + ((P - self.mean_) / self.scale_) @ self.coef_[1:]

    def predict(self, X: np.ndarray) -> np.ndarray:
        """The model inside its box, continued outside as ``continuation`` says.

        Parameters
        ----------
        X : ndarray, shape (n, n_vars)

        Returns
        -------
        ndarray, shape (n,)
        """
        X = np.asarray(X, dtype=float).reshape(-1, len(self.var_names))
        off, nn = self.off_data(X)
        Xc = np.clip(X, self.lo_, self.hi_)
        Xc[off] = self.anchor_X_[nn[off]] if off.any() else Xc[off]
        out = self._inside(Xc)
        d = X - Xc
        for v in self.held:
            d[:, self.var_names.index(v)] = 0.0
        if self.continuation == "constant" or not d.any():
            return out
        if self.continuation == "slope":
            return out + d @ self.slope_
        E = self._E()
        for j in np.flatnonzero(np.any(d != 0, axis=0)):
            g = (_monomial_grad(Xc, E, j) / self.scale_) @ self.coef_[1:]
            out = out + g * d[:, j]
        return out

    def coefficients(self) -> dict:
        """Coefficients of the raw (unstandardised) monomials, intercept included.

        Returns
        -------
        dict
            ``{term name: coefficient}`` in target units per unit of the term.
        """
        c = self.coef_[1:] / self.scale_
        out = {"1": float(self.coef_[0] - np.sum(np.where(np.isfinite(self.scale_), c * self.mean_, 0.0)))}
        out.update({t: float(v) for t, v in zip(self.terms[1:], c)})
        return out

    def extrapolation(self, X: np.ndarray, weights: np.ndarray | None = None, units: dict | None = None) -> dict:
        """How far ``X`` leaves the fitting box, per variable, and which terms that touched.

        Parameters
        ----------
        X : ndarray, shape (n, n_vars)
            Base variables where the model is applied.
        weights : ndarray, optional
            Per-row weights for the fraction (sample counts of bins).
        units : dict, optional
            Unit of each variable, for the report.

        Returns
        -------
        dict
            ``variables``: per variable some term uses, ``{fit_range, applied_range, below, above,
            fraction_outside, unit}``; ``terms_extrapolated``: terms of a variable that left
            the box; ``terms_continued_linearly``: those of them of order > 1 (replaced by the
            tangent); ``any``: whether anything was extrapolated.
        """
        X = np.asarray(X, dtype=float).reshape(-1, len(self.var_names))
        E = self._E()
        used = [j for j in range(len(self.var_names)) if E[:, j].any()]  # variables some term uses
        out = box_extrapolation([self.var_names[j] for j in used], X[:, used], self.lo_[used], self.hi_[used],
                                weights, units)
        touched, curved = [], []
        for j in used:
            d = out[self.var_names[j]]
            if d["below"] > 0 or d["above"] > 0:
                for e in E:
                    if e[j]:
                        t = term_name(self.var_names, e)
                        if t not in touched:
                            touched.append(t)
                        if sum(e) > 1 and t not in curved:
                            curved.append(t)
        return {"variables": out, "terms_extrapolated": touched, "terms_continued_linearly": curved,
                "continuation": self.continuation, "held": [v for v in self.held if v in out], "any": bool(touched)}


def box_extrapolation(var_names: list, X: np.ndarray, lo, hi, weights=None, units: dict | None = None) -> dict:
    """How far each input leaves its fitting range.

    Parameters
    ----------
    var_names : list of str
        Input names (columns of ``X``).
    X : ndarray, shape (n, d)
        Inputs where a model is applied.
    lo, hi : array_like, shape (d,)
        The fitting range of each input.
    weights : ndarray, optional
        Row weights for the fraction outside.
    units : dict, optional
        Unit per input name.

    Returns
    -------
    dict
        Per input: ``fit_range``, ``applied_range``, ``below`` and ``above`` (how far beyond the
        range, >= 0), ``fraction_outside`` and ``unit``.
    """
    X = np.asarray(X, dtype=float).reshape(len(X), -1)
    w = np.ones(len(X)) if weights is None else np.asarray(weights, dtype=float)
    out = {}
    for j, name in enumerate(var_names):
        a, b = float(lo[j]), float(hi[j])
        x = X[:, j]
        outside = (x < a) | (x > b)
        out[name] = {"fit_range": [a, b], "applied_range": [float(x.min()), float(x.max())],
                     "below": max(0.0, a - float(x.min())), "above": max(0.0, float(x.max()) - b),
                     "fraction_outside": float(w[outside].sum() / w.sum()) if len(w) else 0.0,
                     "unit": (units or {}).get(name, "")}
    return out


def tangent_continuation(predict, X: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Any regression model inside the box [lo, hi], continued along its tangent plane outside.

    For a row outside the box, ``f(x_c) + grad f(x_c) . (x - x_c)`` with ``x_c`` the nearest
    point of the box and the gradient by a one-sided finite difference pointing into the box.

    Parameters
    ----------
    predict : callable
        ``predict(X) -> ndarray`` of the model.
    X : ndarray, shape (n, d)
        Inputs.
    lo, hi : ndarray, shape (d,)
        The box the model was fitted on.

    Returns
    -------
    ndarray, shape (n,)
    """
    X = np.asarray(X, dtype=float)
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    Xc = np.clip(X, lo, hi)
    base = np.asarray(predict(Xc), dtype=float)
    out = base.copy()
    d = X - Xc
    rows = np.flatnonzero(np.any(d != 0, axis=1))
    if rows.size == 0:
        return out
    for j in np.flatnonzero(np.any(d[rows] != 0, axis=0)):
        h = 1e-3 * (hi[j] - lo[j])
        if h <= 0:
            continue  # no extent on this input: the model cannot have learnt a slope along it
        r = rows[d[rows, j] != 0]
        step = np.where(d[r, j] > 0, -h, h)  # into the box
        Xh = Xc[r].copy()
        Xh[:, j] += step
        g = (np.asarray(predict(Xh), dtype=float) - base[r]) / step
        out[r] = out[r] + g * d[r, j]
    return out


# --------------------------------------------------------------------------------------------
# Forward-chained validation
# --------------------------------------------------------------------------------------------
def _cuts(counts: np.ndarray, segment: np.ndarray, n_folds: int, min_train_fraction: float,
          by_segment: bool) -> np.ndarray:
    """First bin of each scored block, fitting on the bins before it."""
    n = len(counts)
    cum = np.cumsum(counts) / counts.sum()
    fr = min_train_fraction + (1.0 - min_train_fraction) * np.arange(n_folds) / n_folds
    cuts = np.searchsorted(cum, fr, side="right")
    if by_segment:
        starts = np.flatnonzero(np.diff(segment)) + 1
        if starts.size == 0:
            return np.array([], dtype=int)
        cuts = starts[np.abs(starts[None, :] - cuts[:, None]).argmin(axis=1)]
    return np.unique(np.clip(cuts, 1, n))


def chained_folds(bins: Bins, n_folds: int = 4, min_train_fraction: float = 0.5, by_segment: bool = False,
                  directions: tuple = ("forward", "backward")) -> list[tuple[np.ndarray, np.ndarray]]:
    """Chained folds over bins: fit on one side of a cut, score the next block on the other.

    Parameters
    ----------
    bins : Bins
        The training record's bins.
    n_folds : int
        Scored blocks per direction.
    min_train_fraction : float
        The first fold of a direction is fitted on this fraction of the samples; the rest is
        cut into ``n_folds`` blocks of equal sample count.
    by_segment : bool
        Cut only at segment boundaries (a record of bursts): each cut moves to the nearest
        boundary; folds that become empty are dropped.
    directions : tuple of {"forward", "backward"}
        ``forward``: fit on the past, score the next block; ``backward``: the mirror image, fit
        on the future and score the block before it (a model meant for another record is used
        on temperatures seen in either order).

    Returns
    -------
    list of (ndarray, ndarray)
        Bin indices fitted on and scored, per fold.
    """
    n = len(bins)
    folds = []
    for direction in directions:
        if direction == "forward":
            cuts = _cuts(bins.counts, bins.segment, n_folds, min_train_fraction, by_segment)
            edges = np.concatenate((cuts, [n]))
            folds += [(np.arange(a), np.arange(a, b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]
        elif direction == "backward":
            cuts = n - _cuts(bins.counts[::-1], bins.segment[::-1], n_folds, min_train_fraction, by_segment)
            edges = np.concatenate(([0], cuts[::-1]))
            folds += [(np.arange(b, n), np.arange(a, b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]
        else:
            raise ValueError(f"unknown direction {direction!r}")
    return folds


def time_blocks(bins: Bins, n_blocks: int = 4, by_segment: bool = False) -> list[np.ndarray]:
    """Contiguous blocks of bins of about equal sample count (cut between bursts when ``by_segment``).

    Parameters
    ----------
    bins : Bins
    n_blocks : int
    by_segment : bool

    Returns
    -------
    list of ndarray
        Bin indices per block (empty blocks dropped).
    """
    cuts = _cuts(bins.counts, bins.segment, n_blocks - 1, 1.0 / n_blocks, by_segment) if n_blocks > 1 else []
    edges = np.concatenate(([0], cuts, [len(bins)]))
    return [np.arange(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


#: A whole-range slope is used beyond the range only when it differs from zero at this two-sided
#: significance level (Student t over the record's time blocks).
SLOPE_ALPHA = 0.05


def slope_significance(X: np.ndarray, y: np.ndarray, w: np.ndarray, blocks: list[np.ndarray],
                       var_names: list) -> dict:
    """Whether the slope of a first-order model in each variable is reproducible from block to block.

    The first-order model is refitted on each contiguous block of the record; the standard error
    of each variable's whole-range slope is the scatter of the block slopes (each weighted by the
    block's spread of that variable, so a block where it hardly moves counts little) over the
    root of the number of blocks. Time blocks, not samples, carry the error: slow noise makes
    neighbouring samples agree, blocks do not.

    Parameters
    ----------
    X : ndarray, shape (n, n_vars)
        Base variables per bin.
    y, w : ndarray
        Target and weights per bin.
    blocks : list of ndarray
        From :func:`time_blocks`.
    var_names : list of str

    Returns
    -------
    dict
        Per variable: ``slope``, ``standard_error``, ``t``, ``t_critical`` (two-sided Student t at
        :data:`SLOPE_ALPHA` with one degree of freedom fewer than the usable blocks) and
        ``significant``; with fewer than three usable blocks nothing is significant.
    """
    def fit(idx):
        Xi = X[idx] - np.average(X[idx], axis=0, weights=w[idx])
        r = np.sqrt(w[idx])
        coef = np.linalg.lstsq(np.column_stack([np.ones(len(idx)), Xi]) * r[:, None], y[idx] * r, rcond=1e-10)[0]
        return coef[1:], (w[idx][:, None] * Xi * Xi).sum(axis=0)

    whole, _ = fit(np.arange(len(y)))
    per = [fit(b) for b in blocks if len(b) > X.shape[1] + 1]
    out = {}
    for j, name in enumerate(var_names):
        sb = np.array([p[0][j] for p in per])
        wb = np.array([p[1][j] for p in per])
        ok = wb > 0
        if ok.sum() < 3:
            out[name] = {"slope": float(whole[j]), "standard_error": None, "t": None, "t_critical": None,
                         "significant": False}
            continue
        sb, wb = sb[ok], wb[ok]
        mean = np.sum(wb * sb) / wb.sum()
        se = float(np.sqrt(np.sum(wb * (sb - mean) ** 2) / ((len(sb) - 1) * wb.sum())))
        t = abs(whole[j]) / se if se > 0 else np.inf
        tc = float(student_t.ppf(1.0 - SLOPE_ALPHA / 2.0, len(sb) - 1))
        out[name] = {"slope": float(whole[j]), "standard_error": se, "t": float(t), "t_critical": tc,
                     "significant": bool(t >= tc)}
    return out


def principal_slope_significance(X: np.ndarray, y: np.ndarray, w: np.ndarray, blocks: list[np.ndarray]) -> dict:
    """Whether the drift's slope along the principal direction of collinear variables is reproducible.

    Variables that all follow one cause (a die temperature, a case temperature and a quadrature
    that all follow the oven) have individual slopes the blocks cannot pin down while their
    joint slope along the data is sharp. The variables are standardised, projected on their first
    principal component (weighted by ``w``), and :func:`slope_significance` tests the slope on
    that projection.

    Parameters
    ----------
    X : ndarray, shape (n, n_vars)
    y, w : ndarray
        Target and weights per bin.
    blocks : list of ndarray
        From :func:`time_blocks`.

    Returns
    -------
    dict
        As one variable of :func:`slope_significance`, with ``direction`` (the component's
        loadings on the standardised variables) and ``explained_variance_ratio``.
    """
    sw = w / w.sum()
    mu = sw @ X
    sd = np.sqrt(sw @ (X - mu) ** 2)
    Z = (X - mu) / np.where(sd > 0, sd, 1.0)
    _, sv, vt = np.linalg.svd(Z * np.sqrt(sw)[:, None], full_matrices=False)
    u = vt[0] * np.sign(vt[0][np.argmax(np.abs(vt[0]))])
    out = slope_significance((Z @ u)[:, None], y, w, blocks, ["pc1"])["pc1"]
    out.update({"direction": [float(v) for v in u],
                "explained_variance_ratio": float(sv[0] ** 2 / np.sum(sv ** 2)) if np.sum(sv ** 2) > 0 else 1.0})
    return out


@dataclass
class Candidate:
    """One structure to score.

    Parameters
    ----------
    name : str
        Readable name, e.g. ``"order 2 + dT/dt (120 s)"``.
    key : object
        Which base-variable matrix it uses (see :func:`select`).
    var_names : list of str
        Base variable names.
    exponents : list of tuple of int
        Monomial terms.
    settings : dict
        What the candidate stands for (order, smoothing...), reported back.
    """

    name: str
    key: object
    var_names: list
    exponents: list
    settings: dict = field(default_factory=dict)

    def model(self) -> MonomialModel:
        """A fresh, unfitted model of this structure (and of its continuation, once chosen)."""
        return MonomialModel(list(self.var_names), [tuple(e) for e in self.exponents],
                             self.settings.get("continuation", "tangent"), tuple(self.settings.get("held", ())),
                             bool(self.settings.get("anchor", False)))

    @property
    def n_coef(self) -> int:
        """Coefficients including the intercept."""
        return 1 + len(self.exponents)


@dataclass
class Selection:
    """The outcome of :func:`select`: the chosen candidate and every candidate's score.

    Parameters
    ----------
    chosen : Candidate
    best : Candidate
        The lowest score (differs from ``chosen`` only under the one-standard-error rule).
    table : list of dict
        Per candidate: ``name``, ``n_coef``, ``settings``, ``validation_rms`` (pooled),
        ``fold_mse``, ``excess_mse_over_best`` and its ``standard_error``, ``within_one_se``.
    folds : list of dict
        Per fold: bins fitted and scored, time span scored.
    rule : str
    notes : list of str
    """

    chosen: Candidate
    best: Candidate
    table: list
    folds: list
    rule: str
    notes: list = field(default_factory=list)

    def report(self) -> dict:
        """JSON-ready summary.

        Returns
        -------
        dict
        """
        return {"chosen": self.chosen.name, "chosen_settings": self.chosen.settings, "best_score": self.best.name,
                "rule": self.rule, "folds": self.folds, "candidates": self.table, "notes": list(self.notes)}


#: Selection rules.
RULES = ("one-se", "best")


#: Continuations beyond the training range, the most conservative first.
CONTINUATIONS = ("constant", "slope", "tangent")


def _inside_share(R: np.ndarray | None, tr: np.ndarray, va: np.ndarray, w: np.ndarray) -> float:
    """Share of a fold's scored samples inside the box it was fitted on."""
    if R is None or R.shape[1] == 0:
        return 1.0
    lo, hi = R[tr].min(axis=0), R[tr].max(axis=0)
    ins = np.all((R[va] >= lo) & (R[va] <= hi), axis=1)
    return float(w[va][ins].sum() / w[va].sum())


def select(candidates: list[Candidate], base: dict, y: np.ndarray, w: np.ndarray,
           folds: list[tuple[np.ndarray, np.ndarray]], bins_t_s: np.ndarray | None = None,
           rule: str = "best", range_vars: np.ndarray | None = None, continuation: str = "auto",
           blocks: list[np.ndarray] | None = None) -> Selection:
    """Score every candidate on chained folds; choose one, then how it continues beyond its range.

    Every candidate forecasts each fold's scored block as it will be used: beyond the range it
    was fitted on, it continues from its edge value along the slope of a line fitted on that
    range. The lowest pooled score wins (``rule="best"``; ``"one-se"``: the simplest candidate
    within one standard error of it). The chosen model then continues beyond the training range
    along the whole-range slope of each variable that slope is significant for
    (:func:`slope_significance` over the record's time blocks), and is held constant along the
    others.

    Parameters
    ----------
    candidates : list of Candidate
        In order of preference among equals (simplest first is customary).
    base : dict
        ``{candidate.key: ndarray (n_bins, n_vars)}``, the base variables per bin.
    y : ndarray
        Target per bin.
    w : ndarray
        Bin weights (sample counts).
    folds : list
        From :func:`chained_folds`; with no fold the simplest candidate is taken.
    bins_t_s : ndarray, optional
        Bin times, for the fold report.
    rule : {"best", "one-se"}
        The best score, or the simplest candidate within one standard error of it.
    range_vars : ndarray, shape (n_bins, k), optional
        Variables whose fitted range each fold reports how much of its forecast left.
    continuation : {"auto", "constant", "slope", "tangent"}
        How the chosen model continues beyond its training range: as above (``"auto"``), or
        fixed.
    blocks : list of ndarray, optional
        Contiguous blocks of the record (:func:`time_blocks`) for :func:`slope_significance`;
        None: every slope counts as significant.

    Returns
    -------
    Selection
        ``chosen`` carries ``settings["continuation"]`` and ``settings["held"]``.
    """
    if rule not in RULES:
        raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
    if continuation not in ("auto",) + CONTINUATIONS:
        raise ValueError(f"continuation must be 'auto' or one of {CONTINUATIONS}, got {continuation!r}")
    notes = []
    fold_info = []
    for tr, va in folds:
        info = {"fit_bins": int(len(tr)), "scored_bins": int(len(va)),
                "scored_inside_fit_range": _inside_share(range_vars, tr, va, w)}
        if bins_t_s is not None:
            info["scored_from_s"], info["scored_to_s"] = float(bins_t_s[va[0]]), float(bins_t_s[va[-1]])
        fold_info.append(info)
    nf = len(folds)
    mse = np.full((len(candidates), nf), np.inf)
    for i, c in enumerate(candidates):
        X = base[c.key]
        for f, (tr, va) in enumerate(folds):
            if len(tr) <= c.n_coef:
                continue  # under-determined on this fold: it cannot be scored there
            m = c.model().fit(X[tr], y[tr], w[tr])
            m.continuation = c.settings.get("continuation", "slope")
            r = y[va] - m.predict(X[va])
            mse[i, f] = float(np.sum(w[va] * r * r) / np.sum(w[va]))
    fw = np.array([w[va].sum() for _, va in folds])
    finite = np.isfinite(mse).all(axis=1) if nf else np.zeros(len(candidates), dtype=bool)
    if not finite.any():
        ic = min(range(len(candidates)), key=lambda i: candidates[i].n_coef)
        notes.append("too few bins or bursts to validate: the simplest candidate is used")
        table = [{"name": c.name, "n_coef": c.n_coef, "settings": dict(c.settings), "validation_rms": None}
                 for c in candidates]
        ib = ic
    else:
        pooled = np.where(finite, np.sqrt(np.where(finite[:, None], mse, 0.0) @ fw / fw.sum()), np.inf)
        ib = min(range(len(candidates)), key=lambda i: (pooled[i], candidates[i].n_coef))
        table, ok = [], []
        for i, c in enumerate(candidates):
            row = {"name": c.name, "n_coef": c.n_coef, "settings": dict(c.settings),
                   "validation_rms": float(pooled[i]) if finite[i] else None,
                   "fold_mse": [float(v) if np.isfinite(v) else None for v in mse[i]]}
            if finite[i]:
                d = mse[i] - mse[ib]
                se = float(np.std(d, ddof=1) / np.sqrt(nf)) if nf > 1 else 0.0
                row["excess_mse_over_best"], row["standard_error"] = float(d.mean()), se
                row["within_one_se"] = bool(d.mean() <= se)
                if row["within_one_se"]:
                    ok.append(i)
            else:
                row["within_one_se"] = False
                row["note"] = "not scored: more coefficients than bins on a fold"
            table.append(row)
        if rule == "best" or nf < 2:
            ic = ib
            if nf < 2 and rule != "best":
                notes.append("one fold only: no standard error, the best score is taken")
        else:
            ic = min(ok, key=lambda i: (candidates[i].n_coef, pooled[i]))
    chosen = candidates[ic]
    _set_continuation(chosen, base[chosen.key], y, w, blocks, continuation, notes)
    table[ic]["settings"] = dict(chosen.settings)
    return Selection(chosen, candidates[ib], table, fold_info, rule, notes)


def _set_continuation(c: Candidate, X: np.ndarray, y, w, blocks, continuation: str, notes: list) -> None:
    """Whole-range slope along the variables whose slope is significant, constant along the others."""
    fixed = list(c.settings.get("held", ()))
    used = [j for j in range(X.shape[1]) if any(e[j] for e in c.exponents) and c.var_names[j] not in fixed]
    if continuation != "auto":
        c.settings.update({"continuation": continuation, "held": fixed})
        return
    names = [c.var_names[j] for j in used]
    if c.settings.get("slope_test") == "joint" and blocks is not None and used:
        sig = {"principal direction": principal_slope_significance(X[:, used], y, w, blocks)}
        held = [] if sig["principal direction"]["significant"] else list(names)
        c.settings.update({"continuation": c.settings.get("continuation", "slope"), "held": fixed + held,
                           "slope_significance": sig})
        v = sig["principal direction"]
        notes.append("beyond the training range " + ("continued along the tangent plane" if not held else "held constant")
                     + " (joint slope test along the principal direction of " + ", ".join(names) + ": t = "
                     + ("n/a" if v["t"] is None else f"{v['t']:.2g}") + ")")
        return
    sig = slope_significance(X[:, used], y, w, blocks, names) if blocks is not None and used else {}
    held = [n for n, v in sig.items() if not v["significant"]]
    c.settings.update({"continuation": c.settings.get("continuation", "slope"), "held": fixed + held,
                       "slope_significance": sig})
    if held:
        notes.append("beyond the training range held constant along " + ", ".join(
            f"{n} (slope t = " + ("n/a" if sig[n]["t"] is None else f"{sig[n]['t']:.2g}") + ")" for n in held)
            + f": its whole-range slope is not significantly different from zero ({100 * SLOPE_ALPHA:g} % level, "
              "Student t over the record's time blocks)")
    if len(held) < len(used):
        notes.append("beyond the training range continued along the slope of a line fitted on the whole range"
                     + (f" in {', '.join(n for n in names if n not in held)}" if held else ""))
