"""Model selection by forward-chained validation, and drift models that do not extrapolate curvature.

Every compensator with a structure to choose (polynomial order, a dT/dt term, a smoothing
span, a set of auxiliary regressors) chooses it the same way:

1. **Forward-chained folds.** The training record's bins are cut in time: each fold is
   fitted on everything before a cut and scored on the block after it, so every score is a
   forecast, as using the model on a later record is. The cuts lie in the last
   ``1 - min_train_fraction`` of the record (by sample count), and on a record of bursts
   they are moved to the nearest burst boundary (a burst is never split between fitting and
   scoring).
2. **Score.** The pooled RMS of the scored bins' residuals (bins weighted by sample count).
   The *structure* is scored on the forecasts that stay inside the range the fold was fitted
   on (the temperature range, say), where a structure's shape is what is tested; a record
   that only ever leaves its past range (a monotone cooling) is scored on all its forecasts.
3. **Rule.** The candidate with the lowest score (``rule="best"``, the default); among
   equal scores the one with fewer coefficients. ``rule="one-se"`` takes instead the simplest
   candidate whose fold-by-fold mean squared error is within one standard error of the best
   (the "one-standard-error rule"); with the four to eight folds a record affords, that
   standard error is wide and the rule measurably chose too simple a model on simulated oven
   runs, so it is an option, not the default.
4. **Beyond the range.** For the chosen structure, the forecasts that left their fold's
   fitted range choose how the model continues beyond the training range: held at its value
   at the edge (order 0) unless continuing along its tangent there (order 1) forecasts them
   better. Curvature is never extrapolated. With no such forecast the tangent is kept, and
   the report says it was not tested.

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
    """``y = c0 + sum_k c_k prod_j x_j^e_kj``, weighted least squares, tangent continuation outside the box.

    Parameters
    ----------
    var_names : list of str
        Names of the base variables (columns of ``X``).
    exponents : list of tuple of int
        One exponent tuple per term (no constant term: the intercept is always there).
    continuation : {"tangent", "constant"}
        Beyond the box: along the tangent plane at its nearest point (order 1), or held at the
        value there (order 0).
    """

    var_names: list
    exponents: list
    continuation: str = "tangent"
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
        return self

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
        Xc = np.clip(X, self.lo_, self.hi_)
        out = self._inside(Xc)
        if self.continuation == "constant":
            return out
        d = X - Xc
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
                "continuation": self.continuation, "any": bool(touched)}


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
                             self.settings.get("continuation", "tangent"))

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


#: A fold's forecasts inside the fitted range choose the structure when they carry at least
#: this fraction of the scored samples (else all forecasts do).
MIN_INSIDE_FRACTION = 0.05
#: Continuations beyond the training range, lowest order first.
CONTINUATIONS = ("constant", "tangent")


def _inside_mask(R: np.ndarray | None, tr: np.ndarray, va: np.ndarray) -> np.ndarray:
    """Which scored bins lie inside the box the fold was fitted on (all of them without ``R``)."""
    if R is None or R.shape[1] == 0:
        return np.ones(len(va), dtype=bool)
    lo, hi = R[tr].min(axis=0), R[tr].max(axis=0)
    return np.all((R[va] >= lo) & (R[va] <= hi), axis=1)


def select(candidates: list[Candidate], base: dict, y: np.ndarray, w: np.ndarray,
           folds: list[tuple[np.ndarray, np.ndarray]], bins_t_s: np.ndarray | None = None,
           rule: str = "best", range_vars: np.ndarray | None = None, continuation: str = "auto") -> Selection:
    """Score every candidate on forward-chained folds; choose one, then its continuation.

    The structure is chosen on the forecasts that stay inside the range the fold was fitted
    on (``range_vars``), when they carry at least :data:`MIN_INSIDE_FRACTION` of the scored
    samples: that is where a structure's shape matters. Then, for the chosen structure, the
    forecasts that leave the range choose how it continues beyond it: held constant unless
    continuing along the tangent forecasts them better (the lowest order the validation
    supports). With no forecast beyond the range the tangent is kept (said in the notes).

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
        The variables whose training range defines "inside" (e.g. the temperature); None:
        every forecast counts as inside.
    continuation : {"auto", "tangent", "constant"}
        How the chosen model continues beyond its training range: chosen by the forecasts
        beyond their fitted range (``"auto"``), or fixed.

    Returns
    -------
    Selection
        ``chosen`` carries ``settings["continuation"]``.
    """
    if rule not in RULES:
        raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
    notes = []
    fold_info = []
    inside = [_inside_mask(range_vars, tr, va) for tr, va in folds]
    for (tr, va), ins in zip(folds, inside):
        info = {"fit_bins": int(len(tr)), "scored_bins": int(len(va)),
                "scored_inside_fit_range": float(w[va][ins].sum() / w[va].sum())}
        if bins_t_s is not None:
            info["scored_from_s"], info["scored_to_s"] = float(bins_t_s[va[0]]), float(bins_t_s[va[-1]])
        fold_info.append(info)
    if not folds:
        c = min(candidates, key=lambda c: c.n_coef)
        c.settings["continuation"] = "tangent" if continuation == "auto" else continuation
        notes.append("too few bins or bursts to validate: the simplest candidate is used")
        return Selection(c, c, [{"name": c.name, "n_coef": c.n_coef, "settings": c.settings,
                                 "validation_rms": None}], [], rule, notes)
    w_in = np.array([w[va][ins].sum() for (_, va), ins in zip(folds, inside)])
    w_all = np.array([w[va].sum() for _, va in folds])
    use_inside = w_in.sum() >= MIN_INSIDE_FRACTION * w_all.sum()
    notes.append("structure chosen on the forecasts inside each fold's fitted range "
                 f"({100 * w_in.sum() / w_all.sum():.0f} % of the scored samples)" if use_inside else
                 "structure chosen on all forecasts: only "
                 f"{100 * w_in.sum() / w_all.sum():.0f} % of them stay inside the fitted range")
    nf = len(folds)
    sse = np.full((len(candidates), nf), np.inf)
    for i, c in enumerate(candidates):
        X = base[c.key]
        for f, ((tr, va), ins) in enumerate(zip(folds, inside)):
            if len(tr) <= c.n_coef:
                continue  # under-determined on this fold: it cannot be scored there
            m = c.model().fit(X[tr], y[tr], w[tr])
            r = y[va] - m.predict(X[va])
            sel = ins if use_inside else np.ones(len(va), dtype=bool)
            sse[i, f] = float(np.sum(w[va][sel] * r[sel] ** 2))
    fw = w_in if use_inside else w_all
    scored = fw > 0
    finite = np.isfinite(sse[:, scored]).all(axis=1)
    if not finite.any():
        c = min(candidates, key=lambda c: c.n_coef)
        notes.append("no candidate could be fitted on every fold: the simplest candidate is used")
        finite[candidates.index(c)] = True
        sse[candidates.index(c)] = 0.0
    mse = np.where(scored, sse / np.where(scored, fw, 1.0), np.nan)
    pooled = np.where(finite, np.sqrt(np.nansum(np.where(scored, sse, 0.0), axis=1) / fw.sum()), np.inf)
    ib = min(range(len(candidates)), key=lambda i: (pooled[i], candidates[i].n_coef))
    table, ok = [], []
    for i, c in enumerate(candidates):
        row = {"name": c.name, "n_coef": c.n_coef, "settings": dict(c.settings),
               "validation_rms": float(pooled[i]) if finite[i] else None,
               "fold_mse": [float(v) if np.isfinite(v) else None for v in mse[i]]}
        if finite[i]:
            d = (mse[i] - mse[ib])[scored]
            se = float(np.std(d, ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0
            row["excess_mse_over_best"], row["standard_error"] = float(d.mean()), se
            row["within_one_se"] = bool(d.mean() <= se)
            if row["within_one_se"]:
                ok.append(i)
        else:
            row["within_one_se"] = False
            row["note"] = "not scored: more coefficients than bins on a fold"
        table.append(row)
    if rule == "best" or scored.sum() < 2:
        ic = ib
        if scored.sum() < 2 and rule != "best":
            notes.append("one scored fold only: no standard error, the best score is taken")
    else:
        ic = min(ok, key=lambda i: (candidates[i].n_coef, pooled[i]))
    chosen = candidates[ic]
    if continuation == "auto":
        chosen.settings["continuation"], cont_scores = _continuation(chosen, base, y, w, folds, inside, notes)
    else:
        chosen.settings["continuation"], cont_scores = continuation, {}
    table[ic]["continuation_rms_beyond_range"] = cont_scores
    return Selection(chosen, candidates[ib], table, fold_info, rule, notes)


def _continuation(c: Candidate, base: dict, y, w, folds, inside, notes: list) -> tuple[str, dict]:
    """Constant or tangent beyond the fitted range: the lowest order the forecasts beyond it support.

    The tangent is taken only when it forecasts the bins beyond each fold's fitted range better
    than the constant by more than one standard error of the fold-by-fold difference (with a
    single such fold, by any margin).
    """
    X = base[c.key]
    per_fold = []
    for (tr, va), ins in zip(folds, inside):
        out = ~ins
        if not out.any() or len(tr) <= c.n_coef:
            continue
        m = c.model().fit(X[tr], y[tr], w[tr])
        wo = w[va][out]
        mse = {}
        for k in CONTINUATIONS:
            m.continuation = k
            r = y[va][out] - m.predict(X[va][out])
            mse[k] = float(np.sum(wo * r * r) / wo.sum())
        per_fold.append((float(wo.sum()), mse))
    if not per_fold:
        notes.append("no forecast left the fitted range: beyond the training range the model continues "
                     "along its tangent (untested on this record)")
        return "tangent", {}
    wt = np.array([p[0] for p in per_fold])
    rms = {k: float(np.sqrt(np.sum(wt * [p[1][k] for p in per_fold]) / wt.sum())) for k in CONTINUATIONS}
    gain = np.array([p[1]["constant"] - p[1]["tangent"] for p in per_fold])
    se = float(np.std(gain, ddof=1) / np.sqrt(len(gain))) if len(gain) > 1 else 0.0
    pick = "tangent" if gain.mean() > se else "constant"
    notes.append(f"beyond the training range: {pick} continuation (forecasts beyond their fitted range in "
                 f"{len(gain)} folds, RMS " + ", ".join(f"{k} {v:.4g}" for k, v in rms.items())
                 + ("" if pick == "tangent" else "; the tangent is not better by one standard error") + ")")
    return pick, {**rms, "folds": len(gain), "tangent_gain_mse": float(gain.mean()), "standard_error": se}
