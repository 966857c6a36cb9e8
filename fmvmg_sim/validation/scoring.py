"""The diagnosis benchmark's scores: each case's outcome against its withheld label, and the rates over cases.

The diagnoser sees only each case's record and the nominal scenario; the labels are read back by
the scorer after every diagnosis has returned. Scores (measured, never tuned to the labels):

* ``false_alarm_rate``: null cases where any effect was claimed (or the verdict was not "none");
* ``top1`` / ``top2``: single-effect cases above the detection limit (SNR tier "above") whose effect
  is first / in the first two of the ranking, with a verdict other than "none";
* ``pairs_exact``: two-effect cases whose accepted set equals the truth (``pairs_exact_above``: both
  members above the limit; ``pairs_exact_separable``: both members above the limit beside the other, i.e.
  what the other member cannot explain of each is above it, :func:`.cases.separable_snr`; a diagnostic
  beside the target's definition, labels without it count by ``tier``);
* ``truth_in_ambiguity_set``: effect cases whose true effect is accepted or in an ambiguity set;
* ``median_shrink``: held-out gap shrink of the accepted effect when the attribution is right;
* ``param_rel_error_median``: relative error of the recovered parameters when right
  (:func:`param_errors`);
* every rate also by SNR tier, and (``white_noise_tiers``) with the tiers of the former SNR definition
  that counted white block noise only;
* out-of-library cases (only with ``--ool-fraction``; they count neither as null nor as effect cases):
  ``ool_unexplained_rate`` (verdict "unexplained", the right answer, whether or not a library effect
  explains a part of the gap), ``ool_attributed_rate`` (a library effect claimed), ``ool_confident_rate``
  (a library effect claimed with no remainder: confidently mis-attributed), ``ool_none_rate`` (verdict
  "none"), each over all of them and (``_above``) over those above the detection limit;
* ``misses_by_cause``: why each true effect of a missed case (a single effect not first, a pair not exact)
  was missed (:data:`MISS_CAUSES`, :func:`miss_cause`), for single effects above the limit and for pairs;
  each case row holds its own as ``miss``, and (``snr_truth_beyond_answer``, :func:`answer_snr`, computed by
  :func:`run_benchmark` for every wrong answer) how far the answer is from the truth in the record's noise;
* ``partial_when_right``: correct attributions (``top1`` or ``pair_exact``) whose verdict is nevertheless
  "unexplained" (the accepted set leaves a located gap open), over ``right_cases``;
* ``above_by_snr``: top-1 and top-2 of the single effects above the limit in bands of their signature SNR
  (:data:`SNR_BANDS`; the tier is set by the SNR the amplitude was scaled to, so a few cases of the first band
  read just under 10), each with its 95 % interval: where above the limit the misses lie;
* ``training_window_tiers``: top-1 and top-2 of the single effects above the limit whose signature is above it
  on the diagnoser's training window as well (label ``tier_train``, :func:`.cases.training_snr`), beside them
  those below it there: a diagnostic of where the misses lie, beside the target's definition, not in its place
  (labels without ``tier_train`` are not counted in it);
* ``ceiling``: top-1, top-2 and exact pairs as they would read if every miss were put right whose cause the record
  and the forward-chained protocol allow (:func:`ceilings`, :data:`IMPOSSIBLE_CAUSES`): an upper bound on what any
  diagnosis could reach on these cases under that protocol, so that a target beyond it is seen to be out of reach of
  the diagnosis rather than missed by it;
* ``detection_claim``: whether the reports' detection limits hold (:func:`detection_claim`): single effects at or
  above their report's limit for the true effect (``mde_ratio`` >= 1 in the rows), found (accepted or in an
  ambiguity set) and top-2, against those below it, and by :data:`MDE_BANDS`;
* ``ci95``: the 95 % Wilson score interval of each rate above that is a proportion of counted cases
  (:data:`INTERVALS`, :func:`wilson_interval`), so that a rate over a few dozen cases is read with its
  uncertainty and a target can be seen to be met, missed, or not yet decided.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import binomtest

from ..diagnosis.forward import CHANNELS
from ..effects import MODELS
from ..scenario import load_scenario
from .cases import NOISE_LEVEL, snr_beyond, unit_device


def param_errors(effect: str, truth: dict, est: dict) -> list[float]:
    """Relative errors of recovered parameters.

    Each error is relative to ``max(|truth|, low end of the prior range)``: an amplitude drawn far
    below its plausible range (to reach a low SNR) is judged on the scale of a plausible value, not
    on its own near-zero size. Flicker is scored on its equivalent output level (phase and output
    flicker are not separable from the rate output).

    Parameters
    ----------
    effect : str
    truth, est : dict

    Returns
    -------
    list of float
    """
    if effect == "flicker_noise":
        lvl = lambda d: d.get("h_output_dps2", 0.0) + d.get("h_phase_rad2", 0.0) * 200.0 ** 2  # noqa: E731
        t, e = lvl(truth), lvl(est)
        return [abs(e - t) / t] if t > 0 and est else []
    out = []
    for p, v in truth.items():
        e = est.get(p)
        if e is None:
            continue
        ref = max(abs(v), MODELS[effect][p].prior[0])
        out.append(abs(e - v) / ref)
    return out


def wrong_answer(label: dict, result: dict) -> bool:
    """Whether a diagnosis missed its case: a single effect not first, a pair not exact (never a null or an
    out-of-library case, nor a failed diagnosis).

    Parameters
    ----------
    label, result : dict
        The case's label and its diagnosis (``accepted``).

    Returns
    -------
    bool
    """
    truth = sorted(label["effects"])
    if "error" in result or not truth or label.get("out_of_library"):
        return False
    acc = result["accepted"]
    return acc[:1] != truth if len(truth) == 1 else sorted(acc) != truth


def answer_snr(label: dict, result: dict, scenario: str) -> float | None:
    """SNR of a case's true signature beyond the deterministic effects its diagnosis accepted.

    Parameters
    ----------
    label, result : dict
        The case's label and its diagnosis (``accepted``).
    scenario : str
        Nominal scenario (its device is the case generator's).

    Returns
    -------
    float or None
        None when the answer or the truth has no deterministic effect (nothing to compare), or when the
        answer's fit leaves the model's domain.
    """
    det = [a for a in result.get("accepted") or [] if a not in NOISE_LEVEL]
    if not det or all(t in NOISE_LEVEL for t in label["effects"]):
        return None
    noise = [label["noise_model"].get(c) for c in CHANNELS]
    try:
        return snr_beyond(label["record"], unit_device(label, load_scenario(scenario).device_nominal),
                          label["nominal_deviation"], label["effects"], noise, det)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None


#: Detection limit (SNR) of a pair member beyond its partner: the "above" tier's lower edge
#: (:data:`.cases.SNR_TIERS`).
SEPARABLE_SNR_MIN = 10.0

#: Why a true effect was missed, in the order :func:`miss_cause` tests them.
MISS_CAUSES = {
    "one_temperature": "the record's training windows never leave one temperature: an effect that acts only "
                       "through a temperature change is not identifiable there (the design-unidentifiable case)",
    "hidden_by_converter": "extra flicker beside a coarser converter (not judged there; in the benchmark's cases its "
                           "wander lies far below one converter step)",
    "inseparable": "the pair's other member explains this one's signature: beside it, what is left is below the "
                   "detection limit (cases.separable_snr), so no test can tell the pair from the other alone",
    "indistinguishable": "the accepted answer explains the true signature to within the detection limit (the "
                         "truth's SNR beyond the answer, cases.snr_beyond): the record cannot prefer the truth",
    "no_heldout_test": "no held-out fold can test the effect as fitted (its prediction moves no fold by the nats a "
                       "test needs: the signature is absent from the training window or from the held-out blocks)",
    "train_below_limit": "the training window carries the signature below the detection limit (after the nominal "
                         "calibration there: cases.training_snr): forward-chained attribution fits on that window, "
                         "so the record holds the effect mostly in its held-out end",
    "look_alike": "a look-alike explains the same gap (the truth is in the ambiguity set or named as the look-alike)",
    "beside_stronger": "the other member of the pair is at least 100 times stronger and was found",
    "criteria": "fitted and testable, but short of an acceptance criterion (held-out interval, folds, BIC, bounds)",
    "ranked_second": "accepted, but another effect ranked first",
}


def miss_cause(effect: str, truth: list, accepted: list, ambiguous: set, rows: dict, snr_by: dict,
               not_identifiable: list | tuple = (), snr_separable: dict | None = None,
               snr_beyond_answer: float | None = None, snr_train: float | None = None) -> str:
    """Why a true effect is missing from (or not first in) the accepted set: a key of :data:`MISS_CAUSES`.

    Parameters
    ----------
    effect : str
        The true effect.
    truth, accepted : list of str
    ambiguous : set of str
        Every effect named in an ambiguity set.
    rows : dict
        The diagnosis' rows by effect (``folds_testable``, ``why_not``).
    snr_by : dict
        The label's SNR by effect.
    not_identifiable : list of str, optional
        Effects the record's design cannot identify (the report's ``design``, read from the record alone).
    snr_separable : dict, optional
        The label's SNR by effect beyond the pair's other member (:func:`.cases.separable_snr`).
    snr_beyond_answer : float, optional
        The true signature's SNR beyond the accepted effects (:func:`answer_snr`).
    snr_train : float, optional
        A single effect's SNR on the diagnoser's training window (the label's ``snr_train``).

    Returns
    -------
    str
    """
    if effect in accepted:
        return "ranked_second"
    if effect in not_identifiable:
        return "one_temperature"
    if effect == "flicker_noise" and "quantization" in truth:
        return "hidden_by_converter"
    if len(truth) == 2 and (snr_separable or {}).get(effect, np.inf) < SEPARABLE_SNR_MIN:
        return "inseparable"
    if snr_beyond_answer is not None and snr_beyond_answer < SEPARABLE_SNR_MIN:
        return "indistinguishable"
    row = rows.get(effect) or {}
    if row.get("folds_testable") == 0:
        return "no_heldout_test"
    if len(truth) == 1 and snr_train is not None and snr_train < SEPARABLE_SNR_MIN:
        return "train_below_limit"
    if effect in ambiguous or any("look-alike" in w for w in row.get("why_not") or []):
        return "look_alike"
    other = [t for t in truth if t != effect]
    if other and other[0] in accepted and snr_by.get(other[0], 0.0) >= 100.0 * snr_by.get(effect, np.inf):
        return "beside_stronger"
    return "criteria"


#: Miss causes no diagnosis can put right on that record under the forward-chained protocol: an effect that acts only
#: through a temperature change on training windows at one temperature, flicker beside a coarser converter, a pair
#: member the other explains to within the detection limit (label truth: :func:`.cases.separable_snr`), an effect no
#: held-out fold can test, and one the training window carries below the limit. The others (``indistinguishable``,
#: ``look_alike``, ``criteria``, ``beside_stronger``, ``ranked_second``), errors and extra accepted effects count as
#: fixable in :func:`ceilings`, which is therefore an upper bound.
IMPOSSIBLE_CAUSES = ("one_temperature", "hidden_by_converter", "inseparable", "no_heldout_test", "train_below_limit")


def _causes(r: dict) -> set:
    """The miss causes of a case row; ``criteria`` or ``look_alike`` of a single effect whose training window carries
    it below the limit read as ``train_below_limit`` (rows scored before labels carried ``snr_train``; the order of
    :func:`miss_cause`, which tests the training window before those two)."""
    out = set()
    for c in (r.get("miss") or {}).values():
        if (c in ("criteria", "look_alike") and len(r["truth"]) == 1 and r.get("snr_train") is not None
                and r["snr_train"] < SEPARABLE_SNR_MIN):
            c = "train_below_limit"
        out.add(c)
    return out


def ceilings(rows: list[dict]) -> dict:
    """Top-1, top-2 and exact pairs if every miss whose cause the record and protocol allow were put right.

    A missed case counts as reachable unless a missing true effect's cause is in :data:`IMPOSSIBLE_CAUSES`; a case
    whose diagnosis failed, or a pair inexact through an extra accepted effect, counts as reachable.

    Parameters
    ----------
    rows : list of dict
        Case rows of :func:`score` (``truth``, ``tier``, the verdict flags and ``miss``), from one run or pooled.

    Returns
    -------
    dict
        ``{"top1" | "top2": ..., "pairs_exact": ...}``, each ``{"reachable": k, "cases": n, "rate": k / n,
        "ci95": [low, high], "out_of_reach": {cause: cases}}`` over the single effects above the detection limit
        and over all pairs (the denominators of the targets); ``rate`` and ``ci95`` are None with no case.
    """
    out = {}
    for key, sel in (("top1", lambda r: len(r["truth"]) == 1 and r["tier"] == "above"),
                     ("top2", lambda r: len(r["truth"]) == 1 and r["tier"] == "above"),
                     ("pairs_exact", lambda r: len(r["truth"]) == 2)):
        flag = "pair_exact" if key == "pairs_exact" else key
        cases = [r for r in rows if flag in r and sel(r)]
        k, lost = 0, {}
        for r in cases:
            bad = sorted(_causes(r) & set(IMPOSSIBLE_CAUSES)) if not r[flag] else []
            if bad:
                for c in bad:
                    lost[c] = lost.get(c, 0) + 1
            else:
                k += 1
        n = len(cases)
        out[key] = {"reachable": k, "cases": n, "rate": k / n if n else None, "ci95": wilson_interval(k, n),
                    "out_of_reach": lost}
    return out


#: Rates given a 95 % interval in ``ci95``: (rate key, key of the number of cases it is a proportion of).
INTERVALS = (("false_alarm_rate", "null_cases"), ("top1", "single_above"), ("top2", "single_above"),
             ("pairs_exact", "pair_cases"), ("pairs_exact_above", "pair_cases_above"),
             ("pairs_exact_separable", "pair_cases_separable"), ("truth_in_ambiguity_set", "effect_cases_above"))


#: Bands of signature SNR (lower, upper) over which ``above_by_snr`` splits the single effects above the limit.
SNR_BANDS = ((0.0, 20.0), (20.0, 50.0), (50.0, 100.0), (100.0, np.inf))


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> list[float] | None:
    """Wilson score interval of a binomial proportion.

    Parameters
    ----------
    successes, n : int
        Cases that count, out of ``n``.
    confidence : float, optional
        Two-sided confidence level.

    Returns
    -------
    list of float or None
        ``[low, high]``; None when ``n`` is 0.
    """
    if n <= 0:
        return None
    ci = binomtest(int(successes), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    return [float(ci.low), float(ci.high)]


def after_training_note_rates(rows: list[dict]) -> dict:
    """How often the record-design note (:func:`.windows.after_training_note`) fired, by what the case was.

    Parameters
    ----------
    rows : list of dict
        Case rows of :func:`score` (those without ``note_after_training`` are not counted).

    Returns
    -------
    dict
        ``{group: {"fired": k, "cases": n}}`` for null cases, and for single effects above the detection limit:
        top-2 misses whose training window carries the effect below the limit (``miss_train_below``, where the
        note should fire), top-2 misses above it there (``miss_train_above``) and top-2 hits (``hit``, where
        it should stay silent, the truth having closed the gap).
    """
    groups = {"null": lambda r: r["truth"] == [] and "false_alarm" in r,
              "miss_train_below": lambda r: r.get("top2") is False and r["tier"] == "above"
              and r["tier_train"] in ("below", "near"),
              "miss_train_above": lambda r: r.get("top2") is False and r["tier"] == "above"
              and r["tier_train"] == "above",
              "hit": lambda r: r.get("top2") is True and r["tier"] == "above"}
    out = {}
    for name, sel in groups.items():
        v = [r["note_after_training"] for r in rows if "note_after_training" in r and sel(r)]
        out[name] = {"fired": int(sum(v)), "cases": len(v)}
    return out


def score(labels: list[dict], results: list[dict]) -> dict:
    """Score diagnoses against labels.

    Parameters
    ----------
    labels, results : list of dict
        Same order.

    Returns
    -------
    dict
    """
    rows = []
    for lab, res in zip(labels, results):
        truth = sorted(lab["effects"])
        err = "error" in res
        acc = [] if err else res["accepted"]
        ranked = [] if err else res["ranked"]
        amb = set() if err else {x for v in res["ambiguous_with"].values() for x in v}
        claimed = (not err) and (res["verdict"] != "none" or bool(acc))
        r = {"case": lab["case"], "truth": truth, "tier": lab["tier"], "tier_white": lab.get("tier_white", lab["tier"]),
             "tier_separable": lab.get("tier_separable", lab["tier"]), "tier_train": lab.get("tier_train"),
             "snr": lab["snr"], "snr_train": lab.get("snr_train"), "error": res.get("error"),
             "verdict": None if err else res["verdict"], "accepted": acc}
        # "unexplained" beside accepted effects: they explain part of the gap, not where it lies
        partial = bool(not err and acc and res["verdict"] == "unexplained")
        if lab.get("out_of_library"):
            r["out_of_library"] = lab["out_of_library"]["kind"]
            r["ool_unexplained"] = bool(not err and res["verdict"] == "unexplained")
            r["ool_attributed"] = bool(acc)
            r["ool_confident"] = bool(acc and not partial)
            r["ool_none"] = bool(not err and res["verdict"] == "none")
        elif not truth:
            r["false_alarm"] = bool(claimed)
        elif len(truth) == 1:
            t = truth[0]
            r["top1"] = bool(claimed and ranked[:1] == [t] and acc[:1] == [t])
            r["top2"] = bool(claimed and t in ranked[:2] and t in (set(acc) | amb))
            r["in_set"] = bool(t in acc or t in amb)
            ratio = None if err else size_ratio(t, lab["effects"][t], res.get("detection_limits"))
            if ratio is not None:
                r["mde_ratio"] = ratio
                r["mde_power"] = (res.get("detection_limits") or {}).get("power")
        else:
            r["pair_exact"] = bool(sorted(acc) == truth)
            r["pair_one"] = bool(set(acc) & set(truth))
            r["in_set"] = bool(set(truth) <= (set(acc) | amb))
        if res.get("snr_truth_beyond_answer") is not None:
            r["snr_truth_beyond_answer"] = res["snr_truth_beyond_answer"]
        note = ((res.get("design") or {}).get("gap_after_training") or {}) if not err else {}
        if "fires" in note:
            r["note_after_training"] = bool(note["fires"])
        if truth and not lab.get("out_of_library"):
            r["partial"] = partial
            missed = (len(truth) == 1 and not r["top1"]) or (len(truth) == 2 and not r["pair_exact"])
            if missed and not err:
                r["miss"] = {t: miss_cause(t, truth, acc, amb, res.get("rows") or {}, lab.get("snr_by_effect") or {},
                                         (res.get("design") or {}).get("not_identifiable") or (),
                                         lab.get("snr_separable_by_effect"), res.get("snr_truth_beyond_answer"),
                                         lab.get("snr_train"))
                             for t in truth if not (len(truth) == 2 and t in acc)}
        right = [t for t in truth if t in acc]
        if right and not err:
            sh = [res["rows"][t]["shrink"] for t in right if res["rows"].get(t, {}).get("shrink") is not None]
            r["shrink"] = float(np.median(sh)) if sh else None
            errs = []
            for t in right:
                errs += param_errors(t, lab["effects"][t], res["rows"][t].get("params") or {})
            r["param_rel_error"] = float(np.median(errs)) if errs else None
        rows.append(r)

    def rate(key, sel):
        v = [r[key] for r in rows if key in r and sel(r)]
        return (float(np.mean(v)) if v else None), len(v)

    out = {"cases": len(rows), "errors": sum(r["error"] is not None for r in rows)}
    out["false_alarm_rate"], out["null_cases"] = rate("false_alarm", lambda r: True)
    out["top1"], out["single_above"] = rate("top1", lambda r: r["tier"] == "above")
    out["top2"], _ = rate("top2", lambda r: r["tier"] == "above")
    out["pairs_exact"], out["pair_cases"] = rate("pair_exact", lambda r: True)
    out["pairs_exact_above"], out["pair_cases_above"] = rate("pair_exact", lambda r: r["tier"] == "above")
    # pairs whose members each stay above the limit beside the other (what the partner cannot explain of
    # it: cases.separable_snr); beside the target's definition, not in its place
    out["pairs_exact_separable"], out["pair_cases_separable"] = rate("pair_exact",
                                                                      lambda r: r["tier_separable"] == "above")
    out["pairs_at_least_one"], _ = rate("pair_one", lambda r: True)
    out["truth_in_ambiguity_set"], out["effect_cases_above"] = rate("in_set", lambda r: r["tier"] == "above")
    # correct attributions (top-1 right, or a pair's exact set) whose verdict still calls a part unexplained
    out["partial_when_right"], out["right_cases"] = rate(
        "partial", lambda r: r.get("top1") is True or r.get("pair_exact") is True)
    sh = [r["shrink"] for r in rows if r.get("shrink") is not None]
    out["median_shrink"] = float(np.median(sh)) if sh else None
    pe = [r["param_rel_error"] for r in rows if r.get("param_rel_error") is not None]
    out["param_rel_error_median"] = float(np.median(pe)) if pe else None
    ool = [r for r in rows if "out_of_library" in r]
    if ool:
        out["ool_cases"] = len(ool)
        out["ool_cases_above"] = sum(r["tier"] == "above" for r in ool)
        for key in ("ool_unexplained", "ool_attributed", "ool_confident", "ool_none"):
            out[f"{key}_rate"] = rate(key, lambda r: True)[0]
            out[f"{key}_rate_above"] = rate(key, lambda r: r["tier"] == "above")[0]
    # why true effects were missed: each missing member of a missed case (top-1 misses of single effects,
    # inexact pairs), above the detection limit and over all tiers
    out["misses_by_cause"] = {}
    for name, sel in (("single_above", lambda r: len(r["truth"]) == 1 and r["tier"] == "above"),
                      ("pairs", lambda r: len(r["truth"]) == 2),
                      ("pairs_above", lambda r: len(r["truth"]) == 2 and r["tier"] == "above")):
        c = {k: 0 for k in MISS_CAUSES}
        for r in rows:
            if sel(r):
                for cause in r.get("miss", {}).values():
                    c[cause] += 1
        out["misses_by_cause"][name] = c
    out["by_tier"] = {}
    for t in ("below", "near", "above"):
        out["by_tier"][t] = {"single_cases": rate("top1", lambda r: r["tier"] == t)[1],
                             "top1": rate("top1", lambda r: r["tier"] == t)[0],
                             "top2": rate("top2", lambda r: r["tier"] == t)[0],
                             "pair_cases": rate("pair_exact", lambda r: r["tier"] == t)[1],
                             "pairs_exact": rate("pair_exact", lambda r: r["tier"] == t)[0]}
    # the same rates with the tiers of the former SNR definition (white block noise only)
    out["white_noise_tiers"] = {"single_above": rate("top1", lambda r: r["tier_white"] == "above")[1],
                                "top1": rate("top1", lambda r: r["tier_white"] == "above")[0],
                                "top2": rate("top2", lambda r: r["tier_white"] == "above")[0],
                                "pair_cases_above": rate("pair_exact", lambda r: r["tier_white"] == "above")[1],
                                "pairs_exact_above": rate("pair_exact", lambda r: r["tier_white"] == "above")[0]}
    # single effects above the limit, split by whether the training window carries them above it too
    out["training_window_tiers"] = {}
    for name, sel in (("train_above", lambda r: r["tier_train"] == "above"),
                      ("train_below", lambda r: r["tier_train"] in ("below", "near"))):
        k1, n = rate("top1", lambda r: r["tier"] == "above" and sel(r))
        k2, _ = rate("top2", lambda r: r["tier"] == "above" and sel(r))
        out["training_window_tiers"][name] = {
            "single_cases": n, "top1": k1, "top2": k2,
            "top1_ci95": wilson_interval(round(k1 * n), n) if n else None,
            "top2_ci95": wilson_interval(round(k2 * n), n) if n else None}
    out["after_training_note"] = after_training_note_rates(rows)
    out["ceiling"] = ceilings(rows)
    out["above_by_snr"] = []
    for lo, hi in SNR_BANDS:
        band = [r for r in rows if "top1" in r and r["tier"] == "above" and lo <= r["snr"] < hi]
        k1, k2 = sum(r["top1"] for r in band), sum(r["top2"] for r in band)
        out["above_by_snr"].append({"snr_min": lo, "snr_max": None if np.isinf(hi) else hi,
                                    "single_cases": len(band), "top1": k1 / len(band) if band else None,
                                    "top2": k2 / len(band) if band else None,
                                    "top1_ci95": wilson_interval(k1, len(band)),
                                    "top2_ci95": wilson_interval(k2, len(band))})
    # rates are means of booleans: the count is the rate times its number of cases
    out["ci95"] = {k: (wilson_interval(round(out[k] * out[n]), out[n]) if out.get(k) is not None else None)
                   for k, n in INTERVALS}
    out["detection_claim"] = detection_claim(rows)
    out["rows"] = rows
    return out


def size_ratio(effect: str, truth: dict, limits: dict | None) -> float | None:
    """How far a true effect lies above its report's detection limit: the largest ``|value| / limit`` over its
    parameters with a limit.

    Parameters
    ----------
    effect : str
    truth : dict
        ``{param: value}`` (the label's).
    limits : dict or None
        The report's ``detection_limits`` (``{"power", "effects": {effect: {"params": {param: limit or None}}}}``).

    Returns
    -------
    float or None
        0 when every limit lies beyond the search range (nothing detectable); None when the effect has none (a
        noise-level effect, or a report without limits).
    """
    lim = (((limits or {}).get("effects") or {}).get(effect) or {}).get("params") or {}
    lim = {p: v for p, v in lim.items() if p in truth}
    if not lim:
        return None
    r = [abs(float(truth[p])) / v for p, v in lim.items() if v]
    return float(max(r)) if r else 0.0


#: Bands of a true single effect's size over its report's detection limit (``mde_ratio``).
MDE_BANDS = ((0.0, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, np.inf))


def detection_claim(rows: list[dict]) -> dict | None:
    """How the reports' detection limits (:mod:`.detection`) hold: single effects by their size over the limit.

    A report states, for each deterministic effect, the size it would attribute with probability
    :data:`.detection.POWER`. Over the single-effect cases whose truth is at or above that size (``mde_ratio`` >= 1),
    the truth should be found (accepted or in an ambiguity set) in at least that share; below it, less often.

    Parameters
    ----------
    rows : list of dict
        Case rows of :func:`score` (those without ``mde_ratio`` are not counted: noise-level effects, failed
        diagnoses, reports without limits).

    Returns
    -------
    dict or None
        ``above`` and ``below`` (``cases``, ``found``, ``top2``, ``found_ci95``, ``top2_ci95``) and ``bands``
        (the same per :data:`MDE_BANDS`); None when no row has a ratio.
    """
    v = [r for r in rows if r.get("mde_ratio") is not None and len(r["truth"]) == 1]
    if not v:
        return None

    def part(sel):
        s = [r for r in v if sel(r)]
        k_f, k_2 = sum(bool(r["in_set"]) for r in s), sum(bool(r["top2"]) for r in s)
        return {"cases": len(s), "found": k_f, "top2": k_2, "found_ci95": wilson_interval(k_f, len(s)),
                "top2_ci95": wilson_interval(k_2, len(s))}
    powers = sorted({r["mde_power"] for r in v if r.get("mde_power") is not None})
    return {"power": powers[0] if len(powers) == 1 else powers, "above": part(lambda r: r["mde_ratio"] >= 1.0),
            "below": part(lambda r: r["mde_ratio"] < 1.0),
            "bands": [dict(part(lambda r, lo=lo, hi=hi: lo <= r["mde_ratio"] < hi), ratio_min=lo,
                           ratio_max=None if not np.isfinite(hi) else hi) for lo, hi in MDE_BANDS]}
