"""The acceptance criteria: what a candidate explanation must show before it is accepted.

Each criterion is a named object with its docstring (what it guards against), the reason the report gives when
it fails, and a test on one :class:`~.evaluation.Evaluation` (any object with the same attributes: the unit
tests build small ones by hand). A candidate is accepted when it passes every criterion of :data:`CRITERIA`;
:func:`failed_criteria` is the one place its reasons are written.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Delta-BIC a candidate must reach on the training window.
DELTA_BIC_MAX = -10.0
#: A candidate's new parameters must stand this many noise-model standard errors from "no effect".
PARAM_Z_MIN = 2.0
#: Held-out shrink of the gap the baseline leaves that an accepted candidate must reach.
SHRINK_FLOOR = 0.2


@dataclass(frozen=True)
class Criterion:
    """An acceptance criterion: a name, the reason given when it fails, and its test.

    Subclasses implement :meth:`passes`; their docstring says what the criterion guards against.
    """

    name: str
    reason: str

    def passes(self, ev) -> bool:
        """Whether the evaluation ``ev`` passes.

        Parameters
        ----------
        ev : Evaluation

        Returns
        -------
        bool
        """
        raise NotImplementedError

    def why(self, ev) -> str:
        """The reason given when ``ev`` fails (the criterion's own, unless the evaluation carries a sharper one).

        Parameters
        ----------
        ev : Evaluation

        Returns
        -------
        str
        """
        return self.reason


class Fitted(Criterion):
    """The candidate's fit stayed inside the model's domain (a Duffing term past the loop's steady oscillation,
    a Q that turns negative): a model that cannot be evaluated explains nothing."""

    def passes(self, ev) -> bool:  # noqa: D102 - the class docstring says it
        return ev.fit is not None


class HeldOutInterval(Criterion):
    """The pooled held-out log-likelihood gain over the baseline has a block-bootstrap 95 % interval above zero:
    the candidate predicts blocks it was not fitted on better than the baseline, beyond the scatter a slow noise
    gives a gain on a few blocks."""

    def passes(self, ev) -> bool:  # noqa: D102
        return bool(ev.gain.ci[0] > 0)


class FoldsAgree(Criterion):
    """The forward-chained folds carry the candidate (:meth:`~.heldout.Scorer.folds_ok`): two folds pass on their
    own, or the one fold that can test it does, or the folds that can test it do together. Guards against a
    pooled interval won on one lucky stretch of the record."""

    def passes(self, ev) -> bool:  # noqa: D102
        return bool(ev.gain.folds_ok)


class BicImproves(Criterion):
    """Delta-BIC below :data:`DELTA_BIC_MAX` on the training window: the likelihood gain pays for the candidate's
    parameters (a flexible effect otherwise buys a little of any misfit)."""

    def passes(self, ev) -> bool:  # noqa: D102
        return bool(ev.delta_bic < DELTA_BIC_MAX)


class WithinBounds(Criterion):
    """The fitted parameters lie inside their physical bounds and are not pinned at one
    (:func:`~.evaluation.bounds_verdict`): a fit that needs an impossible value is some other gap leaned on."""

    def passes(self, ev) -> bool:  # noqa: D102
        return ev.bound_reason is None

    def why(self, ev) -> str:  # noqa: D102
        return ev.bound_reason or self.reason


class ParameterSignificant(Criterion):
    """One of the candidate's new linear parameters stands :data:`PARAM_Z_MIN` noise-model standard errors from
    zero: the data, not the prior, pulled it away from "no effect"."""

    def passes(self, ev) -> bool:  # noqa: D102
        return bool(ev.param_z > PARAM_Z_MIN)


class ExplainsHeldOutGap(Criterion):
    """The candidate shrinks the held-out gap its baseline leaves by at least :data:`SHRINK_FLOOR`
    (:meth:`~.heldout.Scorer.shrink`: the excess of the held-out residual over the null's noise, summed over the
    channels in units of the null's, at least one held-out sigma squared). A candidate can pass every likelihood
    test on a record whose nominal model fits to within the noise (a null unit), by trimming a noise fluctuation or
    a model floor: it then explains nothing a user could see, and its shrink is near zero."""

    def passes(self, ev) -> bool:  # noqa: D102
        return ev.shrink is not None and ev.shrink >= SHRINK_FLOOR

    def why(self, ev) -> str:  # noqa: D102
        if ev.shrink is None:
            return "no held-out gap above the noise to explain"
        return f"{self.reason} (shrink {ev.shrink:.3g})"


#: The criteria, in the order the report lists a candidate's failures.
CRITERIA: tuple[Criterion, ...] = (
    Fitted("fitted", "the fit left the model's domain"),
    HeldOutInterval("heldout_interval", "held-out gain interval reaches zero"),
    FoldsAgree("folds_agree", "too few held-out folds pass"),
    BicImproves("bic_improves", f"dBIC not below {DELTA_BIC_MAX:g}"),
    WithinBounds("within_bounds", "a parameter outside or pinned at its physical bound"),
    ParameterSignificant("parameter_significant", f"no parameter {PARAM_Z_MIN:g} standard errors from zero"),
    ExplainsHeldOutGap("explains_heldout_gap", f"shrinks the held-out gap by less than {SHRINK_FLOOR:g}"),
)
CRITERIA_BY_NAME = {c.name: c for c in CRITERIA}
#: The fold criterion's reason (a decision rule lets an effect failing only this name a located gap).
FOLDS_REASON = CRITERIA_BY_NAME["folds_agree"].reason


def failed_criteria(ev) -> list[str]:
    """The reasons of the criteria ``ev`` fails (empty: accepted). An unfitted candidate fails only the first.

    Parameters
    ----------
    ev : Evaluation

    Returns
    -------
    list of str
    """
    if ev.fit is None:
        return [CRITERIA[0].why(ev) + (f" ({ev.error})" if getattr(ev, "error", None) else "")]
    return [c.why(ev) for c in CRITERIA[1:] if not c.passes(ev)]
