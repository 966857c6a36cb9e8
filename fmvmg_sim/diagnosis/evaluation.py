"""A candidate's evaluation: one or two library effects fitted beside the nominal knobs and scored held out.

:func:`evaluate` fits the candidate on the training window (:class:`~.model.EffectModel`), refits it on each
fold and scores it against a baseline (:class:`~.heldout.Scorer`); the result is an :class:`Evaluation`, a plain
record of the statistics the acceptance criteria read (:data:`~.criteria.CRITERIA`). Whether it is accepted, and
why not, is the criteria's to say (:attr:`Evaluation.reasons`), in one place.

The bound checks live here: a fitted parameter outside its physical bounds, or pinned at one, is not an
admissible explanation (:func:`bounds_verdict`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..effects import MODELS
from .criteria import CRITERIA_BY_NAME, failed_criteria
from .heldout import HeldOutGain, Scorer
from .model import NONLINEAR, EffectModel, ModelFit

#: A parameter within this fraction of its range of a non-zero physical bound is near it (:func:`near_bound`).
PIN_TOLERANCE = 1e-3
#: A linear parameter near its bound is pinned when lifting the bound lowers the training chi-square by more
#: than this: the 95 % point of chi-square with one degree of freedom (:func:`bounds_verdict`).
PIN_CHI2 = 3.84
#: Parameters attributed only above a floor inside their simulation bounds: (effect, param) -> (floor, why not).
#: Stress relaxation is attributed from an hour up (physics brief section 4: relaxation takes hours to days; a
#: transient of half an hour or less is warm-up, 5-30 min, which the library does not model).
ATTRIBUTION_FLOOR = {("stress_relaxation", "tau_h"): (1.0, "a relaxation faster than an hour (warm-up-like)")}
#: Why a fit outside or pinned at a bound is not admissible (the bound criterion's own reason).
BOUND_REASON = CRITERIA_BY_NAME["within_bounds"].reason


@dataclass
class Evaluation:
    """One candidate explanation, fitted on the training window and scored on held-out blocks.

    Attributes
    ----------
    names : tuple of str
        The effects of the candidate model.
    new : tuple of str
        The effects it adds to its baseline (the rest are the baseline's).
    fit : ModelFit or None
        The fit on the training window (None: the fit left the model's domain, see ``error``).
    preds : dict or None
        Fold predictions (:meth:`~.heldout.Scorer.fold_predictions`).
    gain : HeldOutGain
        Held-out gain over the baseline.
    delta_bic : float
        BIC of the candidate minus the baseline's on the training window.
    bound_reason : str or None
        Why its parameters are not admissible (:func:`bounds_verdict`); None when they are.
    param_z : float
        The largest of its new parameters over its noise-model standard error (:func:`param_z`).
    shrink : float or None
        Held-out shrink of the gap the baseline leaves (:meth:`~.heldout.Scorer.shrink`); None when the
        baseline leaves none.
    error : str or None
    """

    names: tuple
    new: tuple
    fit: ModelFit | None
    preds: dict | None
    gain: HeldOutGain
    delta_bic: float = np.inf
    bound_reason: str | None = None
    param_z: float = 0.0
    shrink: float | None = None
    error: str | None = None
    _reasons: list | None = field(default=None, repr=False)

    @property
    def key(self) -> str:
        """``"a"`` or ``"a+b"`` (sorted)."""
        return "+".join(sorted(self.names))

    @property
    def fitted(self) -> bool:
        """Whether the fit stayed inside the model's domain."""
        return self.fit is not None

    @property
    def params(self) -> dict:
        """Fitted parameters, ``{effect: {param: value}}`` (empty without a fit)."""
        return self.fit.effects if self.fit is not None else {}

    @property
    def reasons(self) -> list:
        """The acceptance criteria it fails, in words (empty: accepted); the criteria's own (:data:`.criteria.CRITERIA`)."""
        if self._reasons is None:
            self._reasons = failed_criteria(self)
        return self._reasons

    @property
    def accepted(self) -> bool:
        """Whether every acceptance criterion holds."""
        return not self.reasons

    def fails_only(self, reason: str) -> bool:
        """Whether ``reason`` is the only criterion it fails.

        Parameters
        ----------
        reason : str

        Returns
        -------
        bool
        """
        return self.reasons == [reason]


def evaluate(scorer: Scorer, names: list, base: dict, base_pred_train: np.ndarray, fixed: dict | None = None,
             k_base: int = 0, new: list | None = None) -> Evaluation:
    """Fit ``names`` (with ``fixed`` nonlinear parameters) and score it against a baseline.

    Parameters
    ----------
    scorer : Scorer
    names : list of str
    base : dict
        Baseline fold predictions.
    base_pred_train : ndarray
        Baseline prediction of the training-window fit.
    fixed : dict, optional
        ``{effect: {nonlinear param: value}}`` held (the first effect of a forward-selected pair).
    k_base : int, optional
        Parameters of the baseline's effects (for Delta-BIC).
    new : list of str, optional
        The effects added to the baseline (default all of ``names``): one of *their* parameters must be
        significant (the baseline's own effect does not vouch for an added one).

    Returns
    -------
    Evaluation
    """
    new = tuple(new if new is not None else names)
    try:
        mf = EffectModel(scorer.f, scorer.cal, names, fixed).fit(scorer.train)
        preds = scorer.fold_predictions(mf.refit)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:  # outside the model's domain
        return Evaluation(tuple(names), new, None, None, HeldOutGain.failed(), error=f"{type(exc).__name__}: {exc}")
    g = scorer.gain(preds, base)
    k = sum(len(MODELS[n]) for n in names) - k_base
    dbic = scorer.delta_bic(mf._ctx["pred"], base_pred_train, k)
    _, reason = bounds_verdict(scorer, mf)
    return Evaluation(tuple(names), new, mf, preds, g, float(dbic), reason, param_z(mf, list(new)),
                      scorer.shrink(preds["heldout"], base["heldout"]))


def near_bound(name: str, param: str, v: float) -> bool:
    """Whether ``v`` lies within :data:`PIN_TOLERANCE` of its range from a non-zero bound.

    A bound at zero is the "no effect" end of an amplitude (a feedthrough capacitance of 0.04 fF is small, not
    pinned), so only non-zero bounds count; nor does a lower bound an attribution floor replaces.

    Parameters
    ----------
    name, param : str
    v : float

    Returns
    -------
    bool
    """
    s = MODELS[name][param]
    eps = PIN_TOLERANCE * (s.hi - s.lo)
    low = s.lo != 0.0 and v - s.lo < eps and (name, param) not in ATTRIBUTION_FLOOR
    return low or (s.hi != 0.0 and s.hi - v < eps)


def bound_check(eff: dict) -> tuple[str | None, list]:
    """The bound rules a set of fitted values can be judged on alone (see :func:`bounds_verdict`).

    Parameters
    ----------
    eff : dict
        ``{effect: {param: value}}``.

    Returns
    -------
    reason : str or None
        Why the values are not admissible (None: they may be).
    near : list of str
        Linear parameters (``"effect.param"``) near a non-zero bound: pinned only if the data pull them past it.
    """
    near = []
    for n, ps in eff.items():
        for p, v in ps.items():
            s = MODELS[n][p]
            if not s.lo <= v <= s.hi:
                return BOUND_REASON, []
            if near_bound(n, p, v):
                if n in NONLINEAR and NONLINEAR[n][0] == p:
                    return BOUND_REASON, []
                near.append(f"{n}.{p}")
    for (n, p), (floor, why) in ATTRIBUTION_FLOOR.items():
        if n in eff and eff[n][p] < floor:
            return why, []
    return None, near


def bounds_verdict(scorer: Scorer, mf: ModelFit, rows: np.ndarray | None = None) -> tuple[bool, str | None]:
    """Whether a fit's parameters are admissible: inside their physical bounds and not pinned at one.

    * Outside ``[lo, hi]``, or a time constant or width within :data:`PIN_TOLERANCE` of a bound: not admissible.
    * A linear parameter near a non-zero bound (:func:`near_bound`) is *pinned* only when the data pull it past
      the bound: solving the training window again with that bound lifted lowers the chi-square (noise model)
      by more than :data:`PIN_CHI2`. An optimum that merely lies near the bound is kept.
    * A parameter below its attribution floor (:data:`ATTRIBUTION_FLOOR`) is not admissible when the data pull it
      there: held at the floor, the training chi-square rises by more than :data:`PIN_CHI2`.

    Parameters
    ----------
    scorer : Scorer
        Its fitter (and training blocks, the default ``rows``).
    mf : ModelFit
    rows : ndarray of bool, optional
        The blocks ``mf`` was fitted on.

    Returns
    -------
    admissible : bool
    reason : str or None
    """
    reason, near = bound_check(mf.effects)
    rows = scorer.train if rows is None else rows
    if reason is not None and reason in {why for _, why in ATTRIBUTION_FLOOR.values()}:
        if _below_floor_strain(mf, rows) <= PIN_CHI2:
            reason, near = bound_check({n: _at_floor(n, ps) for n, ps in mf.effects.items()})
    if reason is None and near and _strained(scorer, mf, near, rows) > PIN_CHI2:
        reason = BOUND_REASON
    return reason is None, reason


def _at_floor(name: str, params: dict) -> dict:
    """``params`` with any parameter below its attribution floor set to the floor."""
    return {p: max(v, ATTRIBUTION_FLOOR[(name, p)][0]) if (name, p) in ATTRIBUTION_FLOOR else v
            for p, v in params.items()}


def _below_floor_strain(mf: ModelFit, rows: np.ndarray) -> float:
    """Training chi-square the fit loses when its parameters below an attribution floor are held at the floor."""
    over = {n: ATTRIBUTION_FLOOR[(n, p)][0] for (n, p) in ATTRIBUTION_FLOOR
            if n in mf.effects and mf.effects[n][p] < ATTRIBUTION_FLOOR[(n, p)][0]}
    if not over or "cost_at" not in mf._ctx:
        return float("inf")
    return float(mf._ctx["cost_at"](over, rows) - mf.solution.cost)


def _strained(scorer: Scorer, mf: ModelFit, names: list, rows: np.ndarray) -> float:
    """Training chi-square the fit gains when the bounds of the ``names`` parameters are lifted."""
    lin = mf.lin
    idx = [lin.names.index(nm) for nm in names if nm in lin.names]
    if not idx:
        return 0.0
    lo, hi = lin.lo.copy(), lin.hi.copy()
    lo[idx], hi[idx] = -np.inf, np.inf
    free = scorer.f.solve(dataclasses.replace(lin, lo=lo, hi=hi), rows)
    return float(mf.solution.cost - free.cost)


def param_z(mf: ModelFit, names: list) -> float:
    """Largest ``|value| / sd`` among the linear parameters of ``names`` (noise-model standard errors).

    The standard errors hold the parameters at an active bound fixed (``Solution.cov_noise``): a calibration
    knob the data push to its bound no longer trades off against the effect.

    Parameters
    ----------
    mf : ModelFit
    names : list of str

    Returns
    -------
    float
        ``inf`` for the thermal lag (its effect is its time constant, scored by the held-out gain).
    """
    z = 0.0
    for n in names:
        if n == "thermal_lag" and "offset_K" in mf.effects.get(n, {}):
            return float("inf")
        for p, sd in mf.sd_noise.get(n, {}).items():
            if np.isfinite(sd) and sd > 0:
                z = max(z, abs(mf.effects[n][p]) / sd)
    return float(z)
