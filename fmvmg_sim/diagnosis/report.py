"""The diagnosis report: assembled from the stages' results (:func:`assemble`), written as JSON (docs/formats.md
section 4) and Markdown (:func:`write_report`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..effects import MODELS
from ..jsonout import strict
from ..record import atomic_write_text
from ..uncertainty import BOUND_TOLERANCES, LAW_OF_EFFECT
from . import localize as loc
from .attribution import TEMPERATURE_DRIVEN, in_sample, separating_experiment
from .criteria import CRITERIA, SHRINK_FLOOR
from .detection import POWER
from .evaluation import Evaluation
from .heldout import MIN_TRAIN_SPAN_K, TOTAL_GAP
from .forward import CHANNELS
from .rules import RULES
from .windows import after_training_note, window_masks, window_stats


def _fmt(v, spec=".4g"):
    return "-" if v is None else format(v, spec) if isinstance(v, (int, float)) else str(v)


def in_sample_lines(hint: dict | None) -> list[str]:
    """The report's section on in-sample candidates (empty without them).

    Parameters
    ----------
    hint : dict or None
        The report's ``in_sample_candidates``: ``note`` and ``candidates`` (each with ``effect``, ``params``,
        ``delta_bic`` and ``heldout``: ``folds_testable``, ``gain``, ``ci``; JSON-clean, so any of them may be None).

    Returns
    -------
    list of str
    """
    if not hint:
        return []
    L = ["## In-sample candidates (not an attribution)", "",
         "Each effect fitted on the whole record, against the nominal model refitted there. No held-out data "
         "checks these: the gap may lie where no training window reaches (the last held-out block). A record "
         "that repeats the excursion, or runs past it, can test them. They say which effect to test next, not that one "
         "acts: on simulated gaps from outside the library this list names a library effect in 31 of 42 cases.", ""]
    for c in hint.get("candidates") or []:
        h = c.get("heldout") or {}
        if h.get("folds_testable") == 0:
            held = "no held-out fold can test it"
        elif h.get("folds_testable") is not None:
            ci = h.get("ci") or [None, None]
            held = (f"tested held out, not accepted (gain {_fmt(h.get('gain'), '.3g')} per block, interval "
                    f"[{_fmt(ci[0], '.3g')}, {_fmt(ci[1], '.3g')}])")
        else:
            held = "not scored held out"
        L.append(f"- {c['effect']}: Delta-BIC {_fmt(c.get('delta_bic'), '.1f')}, parameters "
                 + ", ".join(f"{k} = {_fmt(v, '.4g')}" for k, v in (c.get("params") or {}).items()) + f"; {held}")
    if not hint.get("candidates"):
        L.append("- none: no library effect closes the gap in-sample either.")
    return L + [""]


def detection_lines(det: dict | None, accepted: list) -> list[str]:
    """The detection limits as a table: what this record would have attributed, and what could hide in it.

    Parameters
    ----------
    det : dict or None
        The report's ``detection_limits`` (:func:`.detection.detection_limits` with its ``power``).
    accepted : list of str

    Returns
    -------
    list of str
        Markdown lines; none without limits.
    """
    if not det or not det.get("effects"):
        return []
    pw = det.get("power")
    lead = ("Nothing was attributed: an effect of the sizes below or larger would have been, with probability "
            f"{pw:g}; smaller ones can hide in this record." if not accepted else
            f"The size at which each effect would be attributed on this record, with probability {pw:g}.")
    L = ["", "### Detection limits (from the record's design and the calibrated unit, not from a fit of the effect)", "",
         lead, "",
         "| effect | smallest size attributed | at |", "|---|---|---|"]
    for name, d in det["effects"].items():
        if d.get("error"):
            L.append(f"| {name} | not computed ({d['error']}) | |")
            continue
        parts = []
        for p, v in (d.get("params") or {}).items():
            spec = MODELS[name][p]
            unit = "" if spec.unit == "1" else f" {spec.unit}"
            if v is None or p in d.get("beyond_bound", []):
                parts.append(f"{p}: not detectable here (beyond its physical bound)")
            elif 0 < spec.lo and v < spec.lo:
                parts.append(f"{p}: any value within its bounds (limit {_fmt(v, '.3g')}{unit}, below {spec.lo:g})")
            else:
                parts.append(f"{p}: {_fmt(v, '.3g')}{unit}" + (" (either sign)" if spec.signed else ""))
        at = ", ".join(f"{k} = {_fmt(v, '.3g')}" for k, v in (d.get("at") or {}).items())
        L.append(f"| {name} | {'; '.join(parts)} | {at} |")
    if det.get("knobs_at_bound") and not accepted:
        # (beside an accepted effect a knob at its bound is the effect's doing; here it bears on what could hide)
        L += ["", f"The calibration holds {', '.join(det['knobs_at_bound'])} at the unit's tolerance bound: a knob there "
              "absorbs no more in one direction, so the limit of an effect that knob mimics can be optimistic (the limits "
              "read both signs of each effect for this reason)."]
    L += ["", "Each parameter alone, at the calibrated unit: the nominal knobs (within their tolerance bounds) and the "
          "effect's other parameters refit beside it on each fold's training window, and the acceptance criteria are "
          "simulated on what they leave (the larger limit of the effect's two signs). Noise-level effects "
          "(extra flicker, a coarser converter) are judged by their Allan band and the output lattice instead."]
    return L


def calibration_lines(cal: dict) -> list[str]:
    """The calibration table: each knob's nominal and calibrated value, its uncertainty and tolerance, and what the
    record says of it.

    Parameters
    ----------
    cal : dict
        The report's ``calibration`` (:meth:`~.calibrate.Calibration.to_json`).

    Returns
    -------
    list of str
    """
    L = ["## 1. Calibration (training window)", "",
         "Each knob of the nominal model's stated uncertainty (the device's [tolerance] table), fitted within "
         f"{BOUND_TOLERANCES:g} tolerances of nominal. Deviations are in the knob's unit; 'calibrated' is the "
         "quantity it acts on.", "",
         "| knob | group | nominal | calibrated | sd | deviation | tolerance | identifiable | note |",
         "|---|---|---|---|---|---|---|---|---|"]
    for k, v in cal["parameters"].items():
        asked = v.get("bound_asked_by_record", True)
        note = ("**at its bound**" if v.get("at_bound") and asked
                else "at its bound, not asked by the record" if v.get("at_bound")
                else "beyond its tolerance" if v.get("beyond_tolerance") else "")
        if note and v.get("effect"):
            note += f" (see {v['effect']})"
        L.append(f"| {k} | {v.get('group', '')} | {_fmt(v.get('nominal'), '.6g')} | {_fmt(v.get('calibrated'), '.6g')} "
                 f"| {_fmt(v.get('sd_calibrated'), '.2g')} | {_fmt(v['value'], '.4g')} | {_fmt(v['tolerance'], '.3g')} "
                 f"| {'yes' if v['identifiable'] else 'no'} | {note} |")
    if cal.get("quadrature_sign", 1.0) < 0:
        L += ["", "The unit's quadrature coupling has the sign opposite to the device file's."]
    if cal.get("quadrature_polarity", 1.0) < 0:
        L += ["", "The record's quadrature output has the opposite polarity to the simulator's (its reference wired the "
              "other way): the bias the quadrature leaks through the phase error turns with it."]
    if cal.get("not_identifiable"):
        L += ["", f"Not identifiable from this record (their posterior is not much narrower than their tolerance): "
              f"{', '.join(cal['not_identifiable'])}."]
    asked = cal.get("at_bound_asked", cal.get("at_bound", []))
    flat = [k for k in cal.get("at_bound", []) if k not in asked]
    if flat:
        L += ["", f"At their bound but not asked there by the record ({', '.join(flat)}): releasing the bound would "
              f"lower the objective by less than the calibration's resolution ({_fmt(cal.get('resolution'), '.3g')}); "
              "the objective is flat along them, and any value on that way fits the record as well."]
    if asked:
        laws = [k for k in asked if cal["parameters"][k].get("group") == "law"]
        L += ["", "The record asks for knobs outside the unit's stated uncertainty "
              f"({', '.join(asked)}): the nominal model within its tolerances does not reproduce it."]
        if laws:
            L += [f"A temperature law at its bound ({', '.join(laws)}) is a nominal law off by more than its tolerance: "
                  "its library effect (noted beside it) describes the rest, and is reported when it passes the "
                  "acceptance criteria."]
    return L + [""]


def rules_lines(rep: dict) -> list[str]:
    """The decision rules that fired, in order, and the acceptance criteria every candidate was judged by.

    Parameters
    ----------
    rep : dict

    Returns
    -------
    list of str
    """
    L = ["## Rules that decided", ""]
    L += [f"{i + 1}. **{r['rule']}**: {r['detail']}" for i, r in enumerate(rep.get("rules_fired") or [])]
    crit = (rep.get("rules") or {}).get("criteria") or []
    if crit:
        L += ["", "A candidate is accepted when it passes every criterion: " + "; ".join(
            c["name"] for c in crit) + " (the 'why not' column names those it fails)."]
    return L + [""]


def markdown(rep: dict) -> str:
    """A report a person reads.

    Parameters
    ----------
    rep : dict
        The JSON report (:func:`json_report`).

    Returns
    -------
    str
    """
    L = [f"# Sim-to-real gap diagnosis: {rep['record']['path']}", "",
         f"**Verdict: {rep['verdict']}**" + (f" - accepted: {', '.join(rep['accepted'])}" if rep["accepted"] else ""), ""]
    for row in rep["ranked"]:
        law = row.get("law") if row.get("accepted") else None
        if law:
            L += [f"{row['effect']} is the {law['knob']} law beyond its tolerance: calibrated at "
                  f"{_fmt(law.get('calibrated'), '.4g')} against a nominal {_fmt(law.get('nominal'), '.4g')} "
                  f"(tolerance {_fmt(law['tolerance'], '.3g')}{', at its bound' if law.get('at_bound') else ''}), "
                  f"and {row['effect']} adds " + ", ".join(f"{k} = {_fmt(v, '.3g')}" for k, v in row["params"].items())
                  + " beyond it.", ""]
    if ((rep.get("design") or {}).get("gap_after_training") or {}).get("fires"):
        L += ["A gap lies after the last training window only: see **Record design** under Record.", ""]
    L += rules_lines(rep)
    if rep["ambiguous_with"]:
        L.append("## Ambiguity")
        for a, others in rep["ambiguous_with"].items():
            for o in others:
                L.append(f"- **{a}** vs **{o}**: {rep['separating_experiments'].get(a, {}).get(o, '')}")
        L.append("")
    if rep.get("remainder"):
        rem = rep["remainder"]
        L += ["## Unexplained remainder", ""]
        if rem.get("partial"):
            shrink = {(c["group"], c["name"]): c["shrink"] for c in (rep.get("closure") or {}).get("checked", [])}
            L += [f"The accepted effects ({', '.join(rem['explained_by'])}) pass on held-out data but do not close "
                  "the gap where it lies: with them, these statistics stay beyond the null band and shrink by less "
                  "than half. Something outside the library acts there too.", ""]
            for s_ in rem["significant"][:8]:
                L.append(f"- {s_['group']} / {s_['name']} (Holm p = {s_['p_holm']:.2g} with the accepted effects; "
                         f"shrink {_fmt(shrink.get((s_['group'], s_['name'])), '.2f')})")
        else:
            for s_ in rem["significant"][:8]:
                L.append(f"- {s_['group']} / {s_['name']} (Holm p = {s_['p_holm']:.2g})")
        L.append("")
    L += in_sample_lines(rep.get("in_sample_candidates"))
    r = rep["record"]
    L += ["## Record", "", f"{r['samples']} samples, {r['duration_s'] / 3600:.2f} h at {r['sample_interval_s']:.3g} s; "
          f"channels: {', '.join(r['channels'])}; rate_dps is rate_V over {r.get('scale_factor_V_per_dps', 0):.6g} V "
          "per deg/s.", ""]
    L += _coverage_lines(r, rep.get("settings", {}), rep.get("design"))
    if r.get("converter"):
        L += ["Read through a coarse converter (held-out blocks scored through its expected staircase): " + "; ".join(
            f"{c} (step {v['lsb_V']:.3g} V, noise {v['noise_V']:.2g} V per sample, slow noise {v['slow_noise_V']:.2g} "
            "V per block)" for c, v in r["converter"].items()) + ".", ""]
    iss = r["issues"]
    if iss.get("gaps") or iss.get("nan_samples"):
        L.append(f"Gaps: {len(iss.get('gaps', []))} ({iss.get('gap_total_s', 0):.0f} s missing); "
                 f"NaN samples: {iss.get('nan_samples', {})} (bridged for the model inputs, skipped in the fits).")
        L.append("")
    L += calibration_lines(rep["calibration"])
    L += ["## 2. Where the gap lies (against the re-simulated null, Holm-corrected)", "",
          "| group | statistic | z | p (Holm) | significant |", "|---|---|---|---|---|"]
    off = []
    for g in ("channels", "allan_bands", "regimes"):
        for n, d in rep["localization"][g].items():
            sig = "**yes**" if d["significant"] else "no"
            if not d.get("comparable", True):
                sig, off = "not comparable", off + [n]
            L.append(f"| {g} | {n} | {d['z']:.2f} | {d['p_holm']:.2g} | {sig} |")
    if off:
        L += ["", f"Not comparable: {', '.join(off)}. The record lies more than {-loc.NOT_COMPARABLE_Z:g} null standard "
              "deviations below its null there: the null replicates carry something the record does not, and a gap in "
              "that statistic cannot be located from this null (its attribution scoring is not affected)."]
    L += ["", "## 3. Attribution (held-out, forward-chained)", "",
          "| effect | accepted | params | held-out gain [CI] | folds passed / can test | dBIC | gap before | after | shrink "
          "| why not |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for row in rep["ranked"]:
        ps = ", ".join(f"{k}={_fmt(v)}" for k, v in (row.get("params") or {}).items())
        ci = row.get("heldout_gain_ci")
        g = f"{_fmt(row.get('heldout_gain'))} [{_fmt(ci[0])}, {_fmt(ci[1])}]" if ci else "-"
        L.append(f"| {row['effect']} | {'**yes**' if row['accepted'] else 'no'} | {ps} | {g} | "
                 f"{_fmt(row.get('folds_passed'))} / {_fmt(row.get('folds_testable'))} | "
                 f"{_fmt(row.get('delta_bic'), '.3g')} | {_fmt(row.get('gap_before'))} | "
                 f"{_fmt(row.get('gap_after'))} | {_fmt(row.get('shrink'), '.3f')} | {'; '.join(row.get('why_not') or [])} |")
    L += detection_lines(rep.get("detection_limits"), rep["accepted"])
    c = rep.get("combined")
    if c:
        L += ["", f"## 4. Gap before and after ({' + '.join(c['effects'])}), held-out data", "",
              "| metric | gap before | gap after | shrink |", "|---|---|---|---|"]
        for k, b in c["gap_before"].items():
            L.append(f"| {k} | {_fmt(b)} | {_fmt(c['gap_after'].get(k))} | {_fmt(c['shrink'].get(k), '.3f')} |")
    L += ["", "Gaps are the excess RMS over the null's noise, sqrt(max(0, MSE - noise)); shrink = 1 - G_after/G_before "
          f"on the mean-square excess; an effect is accepted only if it shrinks the gap its baseline leaves by at least "
          f"{_fmt((rep.get('rules') or {}).get('shrink_floor'), 'g')}.", ""]
    return "\n".join(L)


def _coverage_lines(r: dict, settings: dict, design: dict | None = None) -> list[str]:
    """The folds' training and held-out temperatures, where the held-out data extrapolate, and what a record
    held at one temperature cannot identify (``design``, :func:`design_check`), and whether what the
    model leaves lies after the last training window only (``design["gap_after_training"]``,
    :func:`~.windows.after_training_note`)."""
    folds = r.get("folds") or []
    if not folds or "train_C" not in folds[0]:
        return []
    not_scored, span_K = settings.get("folds_not_scored") or [], settings.get("min_train_span_K", 5.0)
    rng = lambda v: f"{v[0]:.1f} to {v[1]:.1f} C" if v else "-"  # noqa: E731
    L = ["| fold | trained on | tested on | held-out blocks outside the training range |", "|---|---|---|---|"]
    for k, f in enumerate(folds):
        note = f" (not scored: its training window spans under {span_K:g} K)" if k in not_scored else ""
        L.append(f"| {k + 1} | {f['train_blocks']} blocks, {rng(f['train_C'])} | {f['test_blocks']} blocks, "
                 f"{rng(f['test_C'])} | {100 * f['test_outside_fraction']:.0f} %{note} |")
    o = r.get("heldout_outside_training_temperatures") or {}
    if o.get("heldout_outside_fraction", 0.0) > 0:
        L += ["", f"{100 * o['heldout_outside_fraction']:.0f} % of the held-out blocks lie outside their fold's "
              f"training temperatures (by up to {o['heldout_outside_max_K']:.1f} K): there a fitted temperature law "
              "extrapolates, and its held-out gain tests the extrapolation as well as the effect."]
    if all(f["train_C"] is None or f["train_C"][1] - f["train_C"][0] < span_K for f in folds):
        L += ["", f"No fold's training window spans {span_K:g} K: no temperature effect can be identified on this "
              f"record. Change the temperature by at least {span_K:g} K well before {folds[0]['test_start_s']:.0f} s, "
              "where the held-out blocks begin."]
        if design and design.get("not_identifiable"):
            L += ["", f"Not identifiable from this record: {', '.join(design['not_identifiable'])}. Each acts only "
                  "through a temperature change: held at one temperature it is at most a constant offset, which the "
                  "nominal calibration absorbs unless it exceeds the unit's tolerances. A stress relaxation, extra "
                  "flicker and a coarser converter can still be identified."]
    after = (design or {}).get("gap_after_training") or {}
    if after.get("fires"):
        worst = max((t for k, t in after["tests"].items() if k.endswith("@after") and t["significant"]),
                    key=lambda t: t["z"])
        L += ["", f"**Record design:** {after['advice']} (mean square {worst['value'] / worst['null_mean']:.1f} "
              f"times the null's there, z {worst['z']:.1f})."]
    return L + [""]


def write_report(rep: dict, out: Path) -> dict:
    """Write ``report.json`` and ``report.md`` into ``out``.

    Parameters
    ----------
    rep : dict
    out : Path

    Returns
    -------
    dict
        The JSON-clean report.
    """
    out.mkdir(parents=True, exist_ok=True)
    cj = json_report(rep)
    atomic_write_text(out / "report.json", json.dumps(cj, indent=2) + "\n")
    atomic_write_text(out / "report.md", markdown(cj))
    return cj


def json_report(rep: dict) -> dict:
    """The report as strict JSON: its private parts (``_plot``) dropped, NaN and infinities as null.

    Parameters
    ----------
    rep : dict

    Returns
    -------
    dict
    """
    return strict(rep, drop_private=True)


def design_check(cover: dict, min_span_K: float = MIN_TRAIN_SPAN_K) -> dict:
    """What the record's temperature design lets the diagnosis identify.

    A temperature law is fitted on a training window; a window that never leaves one temperature does not
    determine it, and a held-out test then scores an arbitrary extrapolation. When no fold's training window
    spans ``min_span_K``, the effects that act only through a temperature change
    (:data:`~.attribution.TEMPERATURE_DRIVEN`) cannot be identified from the record beyond a constant offset (the
    design-unidentifiable case of the diagnosis methods, section 3); a stress relaxation, extra flicker and a
    coarser converter can.

    Parameters
    ----------
    cover : dict
        :meth:`~.data.Prepared.temperature_coverage`.
    min_span_K : float, optional

    Returns
    -------
    dict
        ``train_span_K`` (the widest fold's training span), ``min_train_span_K``,
        ``temperature_laws_identifiable`` and ``not_identifiable`` (effect names; empty when identifiable).
    """
    spans = [f["train_C"][1] - f["train_C"][0] if f.get("train_C") else 0.0 for f in cover["folds"]]
    span = float(max(spans, default=0.0))
    ok = span >= min_span_K
    return {"train_span_K": span, "min_train_span_K": float(min_span_K), "temperature_laws_identifiable": ok,
            "not_identifiable": [] if ok else list(TEMPERATURE_DRIVEN)}


def rank_rows(rows: list[dict], accepted: list[str], ambiguous=()) -> list[dict]:
    """The report's ranking of the candidate rows.

    The verdict's effects come first, in the verdict's order; then its look-alikes (the ambiguity-set members),
    by held-out gain whether or not they passed alone; then the candidates that passed alone, then the rest,
    each of these two groups by held-out gain. A look-alike explains the same gap as well as the accepted effect,
    so it is the runner-up before an effect that passed alone but explains the gap worse.

    Parameters
    ----------
    rows : list of dict
        One per effect, with ``effect``, ``accepted`` (passed alone) and ``heldout_gain``.
    accepted : list of str
        The verdict's effects.
    ambiguous : iterable of str, optional
        The ambiguity-set members.

    Returns
    -------
    list of dict
        The rows, reordered.
    """
    order = {n: i for i, n in enumerate(accepted)}
    amb = set(ambiguous) - set(accepted)

    def key(r):
        group = 0 if r["effect"] in amb else 1 if r["accepted"] else 2
        gain = r["heldout_gain"] if r["heldout_gain"] is not None else -1e300
        return order.get(r["effect"], len(order)), group, -gain

    return sorted(rows, key=key)


def _shrinks(before: dict, after: dict) -> dict:
    return {k: (float(1.0 - after.get(k, np.nan) / b) if b > 0 else None) for k, b in before.items()}


def effect_row(ev: Evaluation, scorer, cal) -> dict:
    """One candidate's row of the ranking (docs/formats.md section 4 keys, and the evaluation's statistics).

    Parameters
    ----------
    ev : Evaluation
        A single effect against the nominal model.
    scorer : Scorer
    cal : Calibration

    Returns
    -------
    dict
    """
    name = ev.names[0]
    before = scorer.gaps(scorer.nominal["heldout"])
    row = {"effect": name, "params": {}, "gap_before": float(np.sqrt(before[TOTAL_GAP])), "gap_after": None,
           "shrink": None, "metric": TOTAL_GAP, "accepted": ev.accepted, "heldout_gain": None,
           "why_not": list(ev.reasons), "criteria": {c.name: c.passes(ev) for c in CRITERIA} if ev.fitted else {}}
    if not ev.fitted:
        row["error"] = ev.error
        return row
    after = scorer.gaps(ev.preds["heldout"])
    mf = ev.fit
    row.update({
        "params": mf.effects[name], "param_sd": mf.sd.get(name, {}), "gap_after": float(np.sqrt(after[TOTAL_GAP])),
        "shrink": ev.shrink, "heldout_gain": ev.gain.gain, "heldout_gain_ci": list(ev.gain.ci),
        "folds_passed": ev.gain.folds_passed, "folds_testable": ev.gain.folds_testable,
        "delta_bic": ev.delta_bic, "in_bounds": ev.bound_reason is None, "param_significant": ev.param_z > 2.0,
        "param_z": ev.param_z,
        # how far the nominal knobs move from their calibration when the effect is fitted beside them
        "nominal_shift": {k: float(mf.theta[k] - v) for k, v in cal.theta.items() if k in mf.theta},
        "shrink_by_metric": _shrinks(before, after)})
    return row


def law_of(effect: str, cal, device) -> dict | None:
    """The temperature law an effect describes beyond its tolerance, as calibrated (None for other effects).

    Parameters
    ----------
    effect : str
    cal : Calibration
    device : Device

    Returns
    -------
    dict or None
        The calibration row of the law's knob (:meth:`~.calibrate.Calibration.to_json`) with its name.
    """
    knob = LAW_OF_EFFECT.get(effect)
    if knob is None or knob.name not in cal.theta:
        return None
    return dict(cal.to_json(device)["parameters"][knob.name], knob=knob.name)


def assemble(*, record_path, prep, fitter, cal, null, where, scorer, att, quant, band, flick_ok, accepted, closure,
             verdict, limits, n_null, seed, wall_s) -> dict:
    """The report of one diagnosis from its stages' results (:mod:`.pipeline`).

    Parameters
    ----------
    record_path : path-like
    prep : Prepared
    fitter : Fitter
    cal : Calibration
    null : Null
    where : Localisation
    scorer : Scorer
    att : Attribution
        The decided attribution (:func:`.attribution.attribute`).
    quant : dict or None
        A coarser converter (:func:`.noise_effects.quantization_candidate`).
    band : dict
        The flicker band of the final model (:meth:`.noise_effects.FlickerBand.judge`).
    flick_ok : bool
        Whether extra flicker is accepted.
    accepted : list of str
    closure : dict or None
        Whether the accepted model closes the located gap (:func:`.localize.closure`).
    verdict : Verdict
    limits : dict
        Detection limits (:func:`.detection.detection_limits`).
    n_null, seed : int
    wall_s : float
        Wall time of the diagnosis so far.

    Returns
    -------
    dict
        docs/formats.md section 4 (``verdict``, ``accepted``, ``ambiguous_with``, ``ranked``, ``localization``) and the
        rest this page's Markdown shows; private arrays for the plots under ``_plot``.
    """
    before = scorer.gaps(scorer.nominal["heldout"])
    ranked = [effect_row(ev, scorer, cal) for ev in att.single.values()]
    ranked.append({"effect": "quantization", "params": {"lsb_V": quant["lsb_V"] if quant else 0.0},
                   "gap_before": None, "gap_after": None, "shrink": 1.0 if quant else None,
                   "metric": "rate_V lattice spacing", "accepted": bool(quant), "heldout_gain": None,
                   "detail": {"on_lattice": quant["on_lattice"]} if quant else {}})
    g_before, g_after = max(band["excess_heldout"], 0.0), abs(band["excess_heldout"] - max(band["excess_train"], 0.0))
    ranked.append({"effect": "flicker_noise",
                   "params": {"h_phase_rad2": 0.0, "h_output_dps2": max(band["excess_train"], 0.0) / (2 * np.log(2))},
                   "gap_before": float(np.sqrt(g_before)), "gap_after": float(np.sqrt(g_after)),
                   "shrink": float(1 - g_after / g_before) if g_before > 0 else None,
                   "metric": "allan_flicker_band_dps", "accepted": flick_ok, "heldout_gain": None,
                   "detail": {"z_heldout": band["z_heldout"], "z_train": band["z_train"],
                              "z_flat_heldout": band["z_flat_heldout"], "z_rise_heldout": band["z_rise_heldout"],
                              "not_identifiable": ["h_phase_rad2 (phase vs output flicker split)"]}})
    combined = None
    if att.final is not None:
        after = scorer.gaps(att.final.preds["heldout"])
        combined = {"effects": list(att.selected), "params": att.final.fit.effects,
                    "gap_before": {k: float(np.sqrt(v)) for k, v in before.items()},
                    "gap_after": {k: float(np.sqrt(v)) for k, v in after.items()}, "shrink": _shrinks(before, after)}
        if len(att.selected) > 1:
            # a pair's members are reported with the joint fit's parameters and the joint shrink
            for r in ranked:
                if r["effect"] in att.selected:
                    r["single_fit_params"] = r.get("params")
                    r["params"] = combined["params"][r["effect"]]
                    r["shrink"] = combined["shrink"].get(TOTAL_GAP)
    amb = {a: list(o) for a, o in att.ambiguous.items() if a in accepted}
    lookalike_of = {o: a for a, others in amb.items() for o in others}
    ranked = rank_rows(ranked, accepted, lookalike_of)
    device = fitter.device0
    for r in ranked:
        r["accepted"] = r["effect"] in accepted
        if r["accepted"]:
            r.pop("why_not", None)
            if r["effect"] in att.notes:
                r["accepted_on"] = att.notes[r["effect"]]
            law = law_of(r["effect"], cal, device)
            if law is not None:
                r["law"] = law
        elif r["effect"] == "flicker_noise" and flick_ok:
            r["why_not"] = ["at most two effects are reported"]
        elif r["effect"] == "flicker_noise":
            r["why_not"] = ["not judged beside a coarser converter (its staircase changes the flicker band)" if quant
                            else "the band's excess rises as tau^2 (a slow wander, not flicker)" if band["wander"]
                            else "the flicker band is within the null's"]
        elif r["effect"] == "quantization":
            r["why_not"] = ["the output's lattice is the nominal converter's"]
        elif r["effect"] in att.notes:
            r["why_not"] = [att.notes[r["effect"]]] + [w for w in r.get("why_not") or [] if w != att.notes[r["effect"]]]
    cover = prep.temperature_coverage()
    design = design_check(cover)
    train = scorer.train
    final_tr = att.final.fit._ctx["pred"] if att.final else cal.lin.predict(cal.solution.x)
    design["gap_after_training"] = after_training_note(
        window_stats(prep, fitter.residual(final_tr), window_masks(prep, train)), null.windows,
        float(prep.block_time_s()[train].max()) - float(prep.t_s[0]) if train.any() else 0.0)
    for r in ranked:
        if r["effect"] in limits:
            r["detectable_from"] = limits[r["effect"]]["params"]
        if not r["accepted"] and r["effect"] in design["not_identifiable"]:
            r["why_not"] = ["not identifiable here: no training window leaves one temperature"] + (r.get("why_not") or [])
    sig = where.significant
    remainder = None
    if sig and not accepted:
        remainder = {"significant": [{"group": g, "name": n, "p_holm": p} for g, n, p in sig], "partial": False}
    elif closure and closure["open"]:
        remainder = {"significant": [{"group": r["group"], "name": r["name"], "p_holm": r["p_holm_after"]}
                                     for r in sorted(closure["open"], key=lambda r: r["p_holm_after"])],
                     "partial": True, "explained_by": list(att.selected)}
    hint = None
    if verdict.verdict == "unexplained" and not accepted:
        cands = in_sample(scorer)
        for c in cands:
            ev = att.single.get(c["effect"])
            c["heldout"] = ({"folds_testable": ev.gain.folds_testable, "gain": ev.gain.gain, "ci": list(ev.gain.ci)}
                            if ev is not None and ev.fitted else {})
        hint = {"note": "each effect fitted on the whole record against the nominal model refitted there; "
                        "not validated on held-out data, so not an attribution", "candidates": cands}
    rules_fired = list(att.fired)
    if quant:
        rules_fired.insert(0, {"rule": "coarse_converter", "detail": f"the rate output sits on a lattice of "
                                                                     f"{quant['lsb_V']:.3g} V"})
    if flick_ok:
        rules_fired.append({"rule": "extra_flicker", "detail": f"the flicker band stands {band['z_heldout']:.1f} null "
                                                               "sds above the null held out"})
    rules_fired.append({"rule": verdict.rule, "detail": verdict.detail})
    quad_nominal = float(np.sign(fitter.device0.values["mechanics"]["quadrature_rate_dps"]))
    calib = cal.to_json(device)
    calib["quadrature_sign"] = quad_nominal
    calib["quadrature_polarity"] = fitter.quadrature_polarity
    calib["temperature_delay_s"] = fitter.delay_s
    folds = prep.folds()
    report = {
        "verdict": verdict.verdict, "accepted": accepted, "ambiguous_with": amb, "ranked": ranked,
        "localization": where.comparison,
        "separating_experiments": {a: {o: separating_experiment(a, o) for o in others} for a, others in amb.items()},
        "remainder": remainder, "closure": closure, "in_sample_candidates": hint, "design": design,
        "rules_fired": rules_fired,
        "rules": {"criteria": [{"name": c.name, "reason": c.reason} for c in CRITERIA],
                  "decision": [r.name for r in RULES], "shrink_floor": SHRINK_FLOOR},
        "detection_limits": {"power": POWER, "effects": limits, "knobs_at_bound": list(cal.at_bound)},
        "primary_metric": TOTAL_GAP, "combined": combined, "calibration": calib,
        "record": {"path": str(record_path), "samples": len(prep.t_s), "duration_s": prep.duration_s,
                   "sample_interval_s": prep.sample_interval_s, "channels": list(prep.channels),
                   "scale_factor_V_per_dps": prep.sf_nominal_V_per_dps, "issues": prep.issues,
                   "converter": {CHANNELS[i]: {"lsb_V": cv.lsb_V, "noise_V": cv.tau_V, "slow_noise_V": cv.slow_V}
                                 for i, cv in fitter.converter.items()},
                   "temperature_C": cover["record_C"],
                   "heldout_outside_training_temperatures": {k: cover[k] for k in (
                       "heldout_outside_fraction", "heldout_outside_max_K", "margin_K")},
                   "folds": [{"test_start_s": f["test_start_s"], "test_end_s": f["test_end_s"],
                              "train_blocks": int(f["train"].sum()), "test_blocks": int(f["test"].sum()), **c}
                             for f, c in zip(folds, cover["folds"])]},
        "settings": {"null_runs": n_null, "seed": seed, "block_s": float(np.median(np.diff(prep.block_time_s()))),
                     "delta_bic_max": -10.0, "alpha_holm": loc.ALPHA, "folds_not_scored": scorer.dropped_folds,
                     "min_train_span_K": MIN_TRAIN_SPAN_K},
        "wall_time_s": wall_s,
    }
    report["_plot"] = dict(prep=prep, fitter=fitter, pred_cal=cal.lin.predict(cal.solution.x),
                           nominal_ho=scorer.nominal["heldout"],
                           final_ho=att.final.preds["heldout"] if att.final else None, final_tr=final_tr,
                           st_meas=where.stats, st_null=null.stats, meas_ho_allan=band["allan_heldout"],
                           before=before, after=(combined or {}).get("gap_after"))
    return report
