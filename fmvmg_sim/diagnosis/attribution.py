"""Attribution: every library effect evaluated on held-out blocks, then the decision rules.

Each deterministic effect is fitted beside the nominal knobs on the training window and scored on the
forward-chained held-out blocks (:func:`~.evaluation.evaluate`); :class:`CandidateFitter` makes the further
evaluations the decision rules ask for (an effect beside an accepted one, a pair fitted from scratch), and
:func:`attribute` runs the rules (:data:`~.rules.RULES`). Noise-level effects (a coarser converter, extra flicker)
are judged apart (:mod:`.noise_effects`).
"""

from __future__ import annotations

import copy
import sys
from typing import Callable

import numpy as np
from tqdm import tqdm

from ..effects import MODELS
from .criteria import DELTA_BIC_MAX, PARAM_Z_MIN
from .evaluation import Evaluation, bounds_verdict, evaluate, param_z
from .fitting import DEVICE_EFFECTS, PATH_EFFECTS
from .heldout import HeldOutGain, Scorer
from .model import NONLINEAR, EffectModel
from .rules import Attribution, decide

#: Relative accuracy of an accepted effect's model: a floor on the scoring sigma of a second effect.
SECOND_EFFECT_REL_FLOOR = 0.01
#: The deterministic library effects (fitted and scored held out).
DETERMINISTIC = tuple(e for e in MODELS if e in DEVICE_EFFECTS or e in PATH_EFFECTS)
#: Effects that change the output only through a change of temperature: on a record held at one temperature each
#: is at most a constant offset, which the nominal knobs absorb, and its temperature law is not determined. A stress
#: relaxation acts through time.
TEMPERATURE_DRIVEN = tuple(e for e in DETERMINISTIC if e != "stress_relaxation")

#: What separates look-alike effects (physics brief section 4, diagnosis methods 2.2 step 8).
SEPARATING = {
    frozenset({"thermal_lag", "temperature_rate"}): "two ramp rates plus 1 h post-ramp holds, with the drive "
        "frequency recorded: a lag offsets the die (f_d) from the sensor and decays in the hold; a gradient "
        "term scales with the ramp rate and leaves f_d on the sensor temperature",
    frozenset({"thermal_lag", "thermal_hysteresis"}): "holds of >= 1 h after each ramp direction: a lag decays "
        "during the hold, hysteresis persists; plot the output against the drive frequency (the die's thermometer)",
    frozenset({"temperature_rate", "thermal_hysteresis"}): "two ramp rates: the gradient term scales with dT/dt, "
        "hysteresis depends only on the temperature path",
    frozenset({"demod_phase_drift", "q_factor_drift"}): "heat the electronics and the MEMS separately, or inject an "
        "electrical tone at the drive frequency into the sense front end (bypasses the mechanics); Q drift also "
        "moves the AGC effort",
    frozenset({"demod_phase_drift", "mode_split_drift"}): "rate-table steps at >= 3 temperatures: the split drift "
        "changes the scale factor, the phase drift does not",
    frozenset({"quadrature_drift", "mode_split_drift"}): "rate-table steps at >= 3 temperatures (split drift moves "
        "the scale factor) and a V_p step (electrostatic split)",
    frozenset({"feedthrough", "q_factor_drift"}): "step VDC at constant amplitude: feedthrough scales as 1/VDC",
    frozenset({"reference_drift", "q_factor_drift"}): "step the AGC set-point: reference drift moves the real "
        "amplitude, Q drift only the effort",
    frozenset({"stress_relaxation", "quadrature_drift"}): "repeat the temperature cycle: relaxation does not "
        "repeat, a temperature law does",
}
DEFAULT_EXPERIMENT = ("record the auxiliary channels (quadrature, drive amplitude, AGC effort, drive frequency) and "
                      "add rate-table steps at >= 3 temperatures, two ramp rates and 1 h post-ramp holds")


def separating_experiment(a: str, b: str) -> str:
    """The experiment that would separate two look-alike effects.

    Parameters
    ----------
    a, b : str

    Returns
    -------
    str
    """
    return SEPARATING.get(frozenset({a, b}), DEFAULT_EXPERIMENT)


class CandidateFitter:
    """The evaluations the decision rules ask for, fitted on the record (:class:`~.rules.Candidates`).

    Parameters
    ----------
    scorer : Scorer
    closure : callable, optional
        ``training-window prediction -> bool or None``: whether a model closes the located gap (None: no
        located gap).
    flicker : callable, optional
        ``training-window prediction -> (rho, K, s) or None``: the rate output's slow-state noise model fitted to
        what the model leaves, when the record carries more flicker than the null (None otherwise).
    """

    def __init__(self, scorer: Scorer, closure: Callable | None = None, flicker: Callable | None = None):
        self.scorer = scorer
        self._closure = closure
        self._flicker = flicker

    def single(self, name: str) -> Evaluation:
        """``name`` alone, against the nominal model.

        Parameters
        ----------
        name : str

        Returns
        -------
        Evaluation
        """
        sc = self.scorer
        return evaluate(sc, [name], sc.nominal, sc.nominal_train_pred)

    def beside(self, first: Evaluation, name: str, scorer: Scorer | None = None) -> Evaluation:
        """``name`` fitted beside the accepted ``first`` (its nonlinear parameter held unless ``name`` has its own),
        scored against ``first`` with :data:`SECOND_EFFECT_REL_FLOOR` of ``first``'s signature added to the scoring
        sigma: the first effect's model is accurate to a fraction of its own signature, and a second effect must
        explain more than that error.

        Parameters
        ----------
        first : Evaluation
        name : str
        scorer : Scorer, optional
            Another scorer (a different noise model); default this one's.

        Returns
        -------
        Evaluation
        """
        sc = scorer or self.scorer
        best = first.names[0]
        if best in NONLINEAR and name in NONLINEAR:
            # one nonlinear parameter is searched per fit
            return Evaluation((best, name), (name,), None, None, HeldOutGain.failed(),
                              error="two time constants or widths are not fitted together")
        fixed = EffectModel(sc.f, sc.cal, [best]).fixed_nonlinear(first.fit.effects) if name in NONLINEAR else {}
        sig1 = np.abs(first.fit._ctx["pred"] - sc.nominal_train_pred)
        with sc.f.extra_score_floor(SECOND_EFFECT_REL_FLOOR * sig1):
            return evaluate(sc, [best, name], first.preds, first.fit._ctx["pred"], fixed,
                            k_base=len(MODELS[best]), new=[name])

    def pair(self, a: str, b: str) -> Evaluation:
        """The pair fitted from scratch against the nominal model; its significance is its weaker member's (each
        member must matter in the joint fit).

        Parameters
        ----------
        a, b : str

        Returns
        -------
        Evaluation
        """
        names = sorted((a, b))
        if a in NONLINEAR and b in NONLINEAR:
            return Evaluation(tuple(names), tuple(names), None, None, HeldOutGain.failed(),
                              error="two time constants or widths are not fitted together")
        sc = self.scorer
        ev = evaluate(sc, names, sc.nominal, sc.nominal_train_pred)
        if ev.fitted:
            ev.param_z = min(param_z(ev.fit, [m]) for m in names)
        return ev

    def beats(self, ev: Evaluation, other: Evaluation) -> bool:
        """Whether ``ev`` gains held out over ``other``'s predictions (interval above zero, folds agree).

        Parameters
        ----------
        ev, other : Evaluation

        Returns
        -------
        bool
        """
        if other.preds is None:
            return True
        g = self.scorer.gain(ev.preds, other.preds)
        return bool(g.ci[0] > 0 and g.folds_ok)

    def closes(self, ev: Evaluation) -> bool | None:
        """Whether ``ev``'s model closes the located gap (None: no gap located, or not judged).

        Parameters
        ----------
        ev : Evaluation

        Returns
        -------
        bool or None
        """
        if self._closure is None or ev is None or not ev.fitted:
            return None
        return self._closure(ev.fit._ctx["pred"])

    def rejudged(self, first: Evaluation, second: str) -> Evaluation | None:
        """The second effect scored again beside ``first`` with the record's own rate noise, when the two-effect
        model leaves more flicker in the rate output than the null holds (None otherwise).

        Parameters
        ----------
        first : Evaluation
        second : str

        Returns
        -------
        Evaluation or None
        """
        sc = self.scorer
        if self._flicker is None or sc.noise_params is None:
            return None
        final = self.beside(first, second)
        params = self._flicker(final.fit._ctx["pred"]) if final.fitted else None
        if params is None:
            return None
        sc2 = copy.copy(sc)
        sc2.noise_params = list(sc.noise_params)
        sc2.noise_params[0] = params
        return self.beside(first, second, scorer=sc2)


def attribute(cands: CandidateFitter, located_gap: bool, progress: bool = False) -> Attribution:
    """Every deterministic effect alone, then the decision rules.

    Parameters
    ----------
    cands : CandidateFitter
    located_gap : bool
        Whether the localisation found a gap beyond the null band.
    progress : bool, optional

    Returns
    -------
    Attribution
    """
    single = {n: cands.single(n) for n in tqdm(DETERMINISTIC, disable=not progress, file=sys.stderr,
                                                desc="attribution", unit="effect")}
    return decide(Attribution(single, located_gap=located_gap), cands)


def in_sample(scorer: Scorer, names: tuple = DETERMINISTIC, n_best: int = 3) -> list[dict]:
    """Effects fitted on every block of the record, ranked by their in-sample Delta-BIC: a hint, not a test.

    A gap that lies after the last training window (a hysteresis seen only on a record's last ramp) can be
    located but not attributed: no training window holds it, so nothing can be scored held out. Fitting
    each effect on the whole record, against the nominal model refitted there, says which one would close it
    in-sample. It is reported apart from the attribution and never accepted.

    Parameters
    ----------
    scorer : Scorer
    names : tuple of str, optional
    n_best : int, optional

    Returns
    -------
    list of dict
        ``{"effect", "params", "delta_bic", "param_z"}``, best first; only fits inside their physical bounds,
        with a parameter :data:`~.criteria.PARAM_Z_MIN` standard errors from zero and Delta-BIC below
        :data:`~.criteria.DELTA_BIC_MAX`.
    """
    rows = np.isfinite(scorer.f.Y).any(axis=1)
    base = scorer.cal.lin.predict(scorer.f.solve(scorer.cal.lin, rows).x)
    out = []
    for n in names:
        try:
            mf = EffectModel(scorer.f, scorer.cal, [n]).fit(rows)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            continue
        dbic = scorer.delta_bic(mf._ctx["pred"], base, len(MODELS[n]), rows=rows)
        z = param_z(mf, [n])
        if dbic < DELTA_BIC_MAX and z > PARAM_Z_MIN and bounds_verdict(scorer, mf, rows)[0]:
            out.append({"effect": n, "params": mf.effects[n], "delta_bic": float(dbic), "param_z": float(z)})
    return sorted(out, key=lambda r: r["delta_bic"])[:n_best]
