"""The decision rules: from the candidates' evaluations to the answer, in a fixed order.

Each rule is a named object whose docstring says what it does and what it guards against. A rule reads the
:class:`Attribution` so far (the evaluations and the answer the earlier rules gave), may ask the
:class:`Candidates` it is given for more evaluations (an effect beside another, a pair), and records itself in
:attr:`Attribution.fired` when it changes the answer; the report lists them. The unit tests drive each rule with
hand-made evaluations and a stand-in for :class:`Candidates`.

No rule knows a particular record: every threshold is a criterion's (:mod:`.criteria`) or stated here with the
reason for its value.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

from ..effects import MODELS
from .criteria import FOLDS_REASON
from .evaluation import Evaluation

#: Single candidates from which pairs are fitted from scratch, and best training fits added to them.
PAIR_STARTS = 2
#: Most effects in an answer (the diagnosis methods' verdicts: none, X, X+Y).
MAX_EFFECTS = 2


class Candidates(Protocol):
    """What the rules may ask for (:class:`.attribution.CandidateFitter` fits them; tests stand in)."""

    def beside(self, first: Evaluation, name: str) -> Evaluation:
        """``name`` fitted beside the accepted ``first`` and scored against it."""

    def pair(self, a: str, b: str) -> Evaluation:
        """The pair fitted from scratch and scored against the nominal model."""

    def beats(self, ev: Evaluation, other: Evaluation) -> bool:
        """Whether ``ev`` gains held out over ``other``'s predictions (interval above zero, folds agree)."""

    def closes(self, ev: Evaluation) -> bool | None:
        """Whether ``ev`` closes the gap the localisation found (None: nothing to close)."""

    def rejudged(self, first: Evaluation, second: str) -> Evaluation | None:
        """The second effect scored again with the record's own rate-output noise (None: no cause to)."""


@dataclass
class Attribution:
    """The answer being built: every evaluation made, the effects selected and why the others are not.

    Attributes
    ----------
    single : dict
        Every deterministic effect alone against the nominal model (:class:`~.evaluation.Evaluation` by name).
    seconds : dict
        Second effects fitted beside the first and scored against it, by the second's name.
    pairs : dict
        Pairs fitted from scratch and scored against the nominal model (``"a+b"``).
    selected : list of str
        The answer's deterministic effects, strongest first.
    final : Evaluation or None
        The evaluation of the selected set.
    ambiguous : dict
        ``{selected effect: [look-alikes]}``.
    notes : dict
        ``{effect: why it is not in the answer though it passed, or what named it}``.
    fired : list of dict
        ``{"rule", "detail"}`` of each rule that changed the answer, in order.
    located_gap : bool
        Whether the localisation found a gap beyond the null band.
    """

    single: dict
    seconds: dict = field(default_factory=dict)
    pairs: dict = field(default_factory=dict)
    selected: list = field(default_factory=list)
    final: Evaluation | None = None
    ambiguous: dict = field(default_factory=dict)
    notes: dict = field(default_factory=dict)
    fired: list = field(default_factory=list)
    located_gap: bool = False

    def fire(self, rule: "Rule", detail: str) -> None:
        """Record that ``rule`` changed the answer.

        Parameters
        ----------
        rule : Rule
        detail : str
        """
        self.fired.append({"rule": rule.name, "detail": detail})


@dataclass(frozen=True)
class Rule:
    """A decision rule: a name and :meth:`apply` (the class docstring says what it does and why)."""

    name: str

    def apply(self, att: Attribution, cands: Candidates) -> None:
        """Apply the rule to ``att`` (in place).

        Parameters
        ----------
        att : Attribution
        cands : Candidates
        """
        raise NotImplementedError


def n_params(ev: Evaluation) -> int:
    """Parameters an evaluation adds to its baseline.

    Parameters
    ----------
    ev : Evaluation

    Returns
    -------
    int
    """
    return sum(len(MODELS[n]) for n in ev.new)


def best_of(evals: list) -> Evaluation | None:
    """The accepted evaluation with the largest held-out gain, or the one with fewer parameters among those whose
    gain reaches its interval (of two explanations the data cannot tell apart, the simpler).

    Parameters
    ----------
    evals : list of Evaluation

    Returns
    -------
    Evaluation or None
    """
    acc = [e for e in evals if e.accepted]
    if not acc:
        return None
    top = max(acc, key=lambda e: e.gain.gain)
    ties = [e for e in acc if e.gain.gain >= top.gain.ci[0]]
    return min(ties, key=lambda e: (n_params(e), -e.gain.gain))


def lookalikes(evals: dict, chosen: Evaluation) -> list:
    """Evaluations whose held-out gain lies inside the chosen one's interval, with admissible parameters and their
    own interval above zero: they explain the same gap as well (the ambiguity set).

    Parameters
    ----------
    evals : dict
        Evaluations by key.
    chosen : Evaluation

    Returns
    -------
    list of Evaluation
    """
    lo = chosen.gain.ci[0]
    return [e for e in evals.values() if e is not chosen and e.fitted and e.bound_reason is None
            and e.gain.gain >= lo and e.gain.ci[0] > 0]


class BestSingle(Rule):
    """The first answer: of the single effects that pass every acceptance criterion, the one with the largest
    held-out gain; one with fewer parameters whose gain reaches its interval takes its place (:func:`best_of`).
    The others that passed are noted as explaining the gap less well."""

    def apply(self, att: Attribution, cands: Candidates) -> None:  # noqa: D102
        best = best_of(list(att.single.values()))
        if best is None:
            return
        att.selected, att.final = [best.names[0]], best
        for n, ev in att.single.items():
            if ev.accepted and n != best.names[0]:
                att.notes[n] = "passes alone; another effect explains the gap better"
        att.fire(self, f"{best.names[0]} passes every criterion with the largest held-out gain "
                       f"({best.gain.gain:.3g} nats per block)")


class SecondBesideFirst(Rule):
    """Forward selection of a second effect: each other deterministic effect is fitted beside the first (the
    first's nonlinear parameter held) and scored against the first alone, with a floor of a per cent of the first's
    signature on the scoring sigma (else the first one's model error buys a spurious second). The best that passes
    every criterion, by :func:`best_of`, joins the answer; its shrink is that of the gap the first leaves."""

    def apply(self, att: Attribution, cands: Candidates) -> None:  # noqa: D102
        if len(att.selected) != 1 or MAX_EFFECTS < 2:
            return
        first = att.final
        for n in att.single:
            if n != att.selected[0]:
                att.seconds[n] = cands.beside(first, n)
        best = best_of(list(att.seconds.values()))
        if best is None:
            return
        second = best.new[0]
        att.selected.append(second)
        att.final = best
        att.fire(self, f"{second} beside {att.selected[0]} passes every criterion (held-out gain "
                       f"{best.gain.gain:.3g} nats per block over the first alone)")


class PairFromScratch(Rule):
    """When no single effect passes, two effects may each mis-fit the other's signature alone: pairs are fitted
    from scratch from the strongest single candidates (the :data:`PAIR_STARTS` best held-out gains with an interval
    above zero, and the best training fits) with every other effect. A pair is accepted when it passes every
    criterion, each member's parameters are significant in the joint fit, and it beats each member alone held out
    (two look-alikes fitted against each other otherwise follow noise)."""

    def apply(self, att: Attribution, cands: Candidates) -> None:  # noqa: D102
        if att.selected or MAX_EFFECTS < 2:
            return
        ev = best_pair(att, cands)
        if ev is None:
            return
        att.selected = sorted(ev.names, key=lambda n: -att.single[n].gain.gain)
        att.final = ev
        att.fire(self, f"no single effect passes; the pair {' + '.join(att.selected)} does, and beats each alone")


def best_pair(att: Attribution, cands: Candidates) -> Evaluation | None:
    """The best pair fitted from scratch that passes as :class:`PairFromScratch` asks (fitting them as needed).

    Parameters
    ----------
    att : Attribution
    cands : Candidates

    Returns
    -------
    Evaluation or None
    """
    single = att.single
    fitted = [n for n, e in single.items() if e.fitted]
    starts = sorted((n for n in fitted if single[n].gain.ci[0] > 0 and single[n].gain.folds_ok),
                    key=lambda n: -single[n].gain.gain)[:PAIR_STARTS]
    starts += [n for n in sorted((n for n in fitted if single[n].delta_bic < -10.0),
                                 key=lambda n: single[n].delta_bic)[:PAIR_STARTS + 1] if n not in starts]
    ok = []
    for a in starts:
        for b in single:
            key = "+".join(sorted((a, b)))
            if b == a:
                continue
            ev = att.pairs.get(key) or cands.pair(a, b)
            att.pairs[key] = ev
            if ev.accepted and all(cands.beats(ev, single[m]) for m in ev.names):
                ok.append(ev)
    return best_of(ok)


class LocatedGapNamed(Rule):
    """When the localisation has found a gap beyond the null band and no effect passed, an effect that fails only
    the fold criterion names it (a record whose design leaves one or two scored folds: the pooled interval, the BIC,
    the bounds, the significance and the held-out shrink all pass). The fold criterion guards against a pooled gain
    won on one stretch when nothing says there is a gap at all; here the localisation says there is."""

    def apply(self, att: Attribution, cands: Candidates) -> None:  # noqa: D102
        if att.selected or not att.located_gap:
            return
        cands_ = [ev for ev in att.single.values() if ev.fitted and ev.fails_only(FOLDS_REASON)]
        if not cands_:
            return
        ev = max(cands_, key=lambda e: e.gain.gain)
        att.selected, att.final = [ev.names[0]], ev
        att.notes[ev.names[0]] = ("names a located gap no effect passed for: every criterion but the fold count "
                                  f"({FOLDS_REASON})")
        att.fire(self, f"{ev.names[0]} names the located gap (it fails only the fold count)")


class PairClosesGap(Rule):
    """One accepted effect that explains part of the located gap but leaves it open may be a bystander that two
    effects, each failing alone on the other's signature, let through: a pair fitted from scratch replaces it when
    the pair passes, gains more held out than the single effect, and closes the located gap. A pair that leaves the
    gap open as well is no better account of where it lies, and the simpler answer stands."""

    def apply(self, att: Attribution, cands: Candidates) -> None:  # noqa: D102
        if len(att.selected) != 1 or cands.closes(att.final) is not False:
            return
        ev = best_pair(att, cands)
        if ev is None or ev.gain.gain <= att.final.gain.gain or cands.closes(ev) is False:
            return
        replaced = att.selected[0]
        att.notes[replaced] = "passes alone but leaves the located gap open; a pair fitted from scratch gains more"
        att.selected = sorted(ev.names, key=lambda n: -att.single[n].gain.gain)
        att.final = ev
        att.fire(self, f"the pair {' + '.join(att.selected)} replaces {replaced}: it closes the located gap")


class SecondRejudged(Rule):
    """When the record's rate output carries more slow noise than the null's noise model holds (extra flicker
    found in its Allan band), a smooth second effect (a temperature-rate term) may have been credited for following
    the wander: it is scored again against the first alone with the rate channel's noise model fitted to what the
    two-effect model leaves, and dropped if it no longer passes."""

    def apply(self, att: Attribution, cands: Candidates) -> None:  # noqa: D102
        if len(att.selected) != 2 or att.final is None or len(att.final.new) != 1:
            return
        first = att.single[att.selected[0]]
        ev = cands.rejudged(first, att.selected[1])
        if ev is None or ev.accepted:
            return
        dropped = att.selected.pop()
        att.final = first
        att.notes[dropped] = "as a second effect, fails with the record's own rate noise (extra flicker found)"
        att.fire(self, f"{dropped} dropped: scored with the record's own rate noise it fails ({'; '.join(ev.reasons)})")


class GapRequired(Rule):
    """No located gap, no attribution: when every statistic of the localisation lies inside the null band, the
    effects selected so far are dropped and the answer is none. Each library effect's own tests (held-out interval,
    folds, BIC, significance, shrink) keep its chance of passing on a unit without any effect small, but every
    deterministic effect of the library is tried on every record, and one of a dozen passes by chance far more
    often than any one does. The localisation's band is drawn from the null re-simulations and Holm-corrected over
    the statistics it reads, so asking for a located gap before an attribution holds the false alarms of the whole
    diagnosis near the band's level. An effect that passes without moving any statistic beyond the band stays in
    the attribution table with the reason. Noise-level effects (judged by the Allan band and the output lattice)
    are not selected here and are not dropped."""

    def apply(self, att: Attribution, cands: Candidates) -> None:  # noqa: D102
        if att.located_gap or not att.selected:
            return
        dropped, att.selected, att.final = att.selected, [], None
        for n in dropped:
            att.notes[n] = "passes its own tests, but no statistic of the localisation lies beyond the null band"
        att.fire(self, f"{' + '.join(dropped)} dropped: no statistic lies beyond the null band, and a chance pass "
                       "among the library's candidates is as likely")


class Ambiguity(Rule):
    """The ambiguity set of each selected effect: the other effects that explain the same gap as well (their
    held-out gain inside its interval, admissible parameters, their own interval above zero; :func:`lookalikes`),
    alone for a single answer, or in its place beside the other member for a pair."""

    def apply(self, att: Attribution, cands: Candidates) -> None:  # noqa: D102
        if not att.selected:
            return
        amb = {}
        first = att.selected[0]
        if len(att.selected) == 1 or att.final.new != att.final.names:
            # a single effect, or the first of a forward-selected pair: its look-alikes alone
            amb[first] = [e.names[0] for e in lookalikes(att.single, att.single[first])]
        if len(att.selected) == 2 and att.final.new != att.final.names:
            # the second of a forward-selected pair: the other second effects beside the same first
            amb[att.selected[1]] = [e.new[0] for e in lookalikes(att.seconds, att.final)]
        elif len(att.selected) == 2:
            # a pair fitted from scratch: pairs that share one member and explain the record as well
            for ev in lookalikes(att.pairs, att.final):
                shared = set(ev.names) & set(att.selected)
                if len(shared) != 1:
                    continue
                kept = shared.pop()
                swapped = next(m for m in att.selected if m != kept)
                alt = next(m for m in ev.names if m != kept)
                amb.setdefault(swapped, [])
                if alt not in amb[swapped]:
                    amb[swapped].append(alt)
        amb = {a: [o for o in others if o not in att.selected] for a, others in amb.items()}
        att.ambiguous = {a: o for a, o in amb.items() if o}
        for a, others in att.ambiguous.items():
            for o in others:
                att.notes[o] = f"look-alike of {a}: explains the same gap (see the ambiguity)"
        if att.ambiguous:
            att.fire(self, "; ".join(f"{a} or {', '.join(o)}" for a, o in att.ambiguous.items()))


#: The decision rules, in the order they are applied.
RULES: tuple[Rule, ...] = (
    BestSingle("best_single"),
    SecondBesideFirst("second_beside_first"),
    PairFromScratch("pair_from_scratch"),
    LocatedGapNamed("located_gap_named"),
    PairClosesGap("pair_closes_gap"),
    SecondRejudged("second_rejudged"),
    GapRequired("gap_required"),
    Ambiguity("ambiguity"),
)


def decide(att: Attribution, cands: Candidates, rules: tuple = RULES) -> Attribution:
    """Apply the decision rules in order.

    Parameters
    ----------
    att : Attribution
        With the single-effect evaluations (and ``located_gap``).
    cands : Candidates
    rules : tuple of Rule, optional

    Returns
    -------
    Attribution
        ``att``, decided.
    """
    for rule in rules:
        rule.apply(att, cands)
    return att


@dataclass(frozen=True)
class Verdict:
    """The verdict of docs/formats.md section 4 and the rule that gave it.

    Attributes
    ----------
    verdict : str
        ``"none"``, ``"explained"``, ``"ambiguous"`` or ``"unexplained"``.
    rule : str
    detail : str
    """

    verdict: str
    rule: str
    detail: str


def verdict(accepted: list, ambiguous: dict, located_gap: bool, gap_left_open: bool) -> Verdict:
    """The verdict from the answer and the localisation.

    * ``none``: nothing accepted and no statistic beyond the null band (Holm-corrected);
    * ``unexplained``: a gap beyond the null band and nothing accepted, or accepted effects that leave the located
      gap open (a partial explanation: something outside the library acts too);
    * ``ambiguous``: accepted effects with look-alikes the record cannot tell apart;
    * ``explained``: otherwise.

    Parameters
    ----------
    accepted : list of str
    ambiguous : dict
    located_gap : bool
    gap_left_open : bool

    Returns
    -------
    Verdict
    """
    if not accepted:
        if located_gap:
            return Verdict("unexplained", "gap_without_effect",
                           "a gap beyond the null band that no library effect passes for")
        return Verdict("none", "no_gap", "no effect passes and every statistic lies inside the null band")
    if gap_left_open:
        return Verdict("unexplained", "gap_left_open", "the accepted effects leave the located gap open")
    if ambiguous:
        return Verdict("ambiguous", "lookalikes", "the accepted effects have look-alikes the record cannot tell apart")
    return Verdict("explained", "explained", "the accepted effects explain the gap")
