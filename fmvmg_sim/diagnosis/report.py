"""The diagnosis report as JSON (CONTRACTS.md section 4) and Markdown."""

from __future__ import annotations

import json
import math
from pathlib import Path

from ..effects import MODELS
from ..record import atomic_write_text
from . import localize as loc


def clean(obj):
    """JSON-safe copy: NaN/inf to None, numpy scalars to Python, private keys dropped.

    Parameters
    ----------
    obj : object

    Returns
    -------
    object
    """
    if isinstance(obj, dict):
        return {str(k): clean(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if hasattr(obj, "item") and not isinstance(obj, (list, dict)):
        try:
            obj = obj.item()
        except (ValueError, AttributeError):
            return None
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    return str(obj)


def _undetermined(row: dict) -> str:
    """`` (N undetermined)`` after a row's fold counts when folds were left out, else ``""``."""
    n = row.get("folds_undetermined")
    return f" ({n} undetermined)" if n else ""


def _fmt(v, spec=".4g"):
    return "-" if v is None else format(v, spec) if isinstance(v, (int, float)) else str(v)


def replaced_first_lines(rf: dict | None) -> list[str]:
    """The paragraph on a forward-selected first effect a look-alike replaced (the report's ``replaced_first``).

    Parameters
    ----------
    rf : dict or None
        ``{"effect", "by", "pair_gain_before", "pair_gain_after"}`` (:func:`.attribute.better_first`).

    Returns
    -------
    list of str
        Markdown lines; none when nothing was replaced.
    """
    if not rf:
        return []
    return [f"{rf['by']} replaces {rf['effect']}, which forward selection chose first: beside the same second "
            f"effect it gains more on held-out data ({rf['pair_gain_after']:.2f} against "
            f"{rf['pair_gain_before']:.2f} nats per held-out block over the nominal model). The two remain "
            "look-alikes (see the ambiguity).", ""]


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


def markdown(rep: dict) -> str:
    """A report a person reads.

    Parameters
    ----------
    rep : dict

    Returns
    -------
    str
    """
    L = [f"# Sim-to-real gap diagnosis: {rep['record']['path']}", "",
         f"**Verdict: {rep['verdict']}**" + (f" - accepted: {', '.join(rep['accepted'])}" if rep["accepted"] else ""), ""]
    if ((rep.get("design") or {}).get("gap_after_training") or {}).get("fires"):
        L += ["A gap lies after the last training window only: see **Record design** under Record.", ""]
    if rep.get("located_gap"):
        L += [f"{rep['located_gap']} names a gap the localisation found (section 2) and no effect passed for: it "
              "passes every held-out criterion but the fold count (its pooled held-out gain is above zero, but too few "
              "of the folds that can test it pass on their own). Weaker evidence than a full pass; a record that "
              "repeats its temperature excursion tests it.", ""]
    L += replaced_first_lines(rep.get("replaced_first"))
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
            for s in rem["significant"][:8]:
                L.append(f"- {s['group']} / {s['name']} (Holm p = {s['p_holm']:.2g} with the accepted effects; "
                         f"shrink {_fmt(shrink.get((s['group'], s['name'])), '.2f')})")
            if rep.get("pair_left_gap_open"):
                L += ["", f"A pair fitted from scratch ({' + '.join(rep['pair_left_gap_open'])}) gains more held out "
                      "but leaves the gap open as well, so it is no better account of where the gap lies and the "
                      "single effect stands."]
        else:
            for s in rem["significant"][:8]:
                L.append(f"- {s['group']} / {s['name']} (Holm p = {s['p_holm']:.2g})")
        L.append("")
    L += in_sample_lines(rep.get("in_sample_candidates"))
    r = rep["record"]
    L += ["## Record", "", f"{r['samples']} samples, {r['duration_s'] / 3600:.2f} h at {r['sample_interval_s']:.3g} s; "
          f"channels: {', '.join(r['channels'])}.", ""]
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
    L += ["## 1. Calibration (training window)", "",
          "| parameter | value | sd | tolerance | identifiable | at its bound |", "|---|---|---|---|---|---|"]
    for k, v in rep["calibration"]["parameters"].items():
        L.append(f"| {k} | {v['value']:.4g} | {v['sd']:.2g} | {v['tolerance']:.3g} | "
                 f"{'yes' if v['identifiable'] else 'no'} | {'**yes**' if v.get('at_bound') else ''} |")
    if rep["calibration"].get("at_bound"):
        L += ["", "The nominal model needs parameters outside the unit's tolerance "
              f"({', '.join(rep['calibration']['at_bound'])}): the nominal model alone cannot reproduce the record."]
    L += ["", "## 2. Where the gap lies (against the re-simulated null, Holm-corrected)", "",
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
              "that statistic cannot be located from this null (its attribution scoring is not affected). For the drive "
              "frequency on a record with temperature ramps this is the null's own artefact: its replicates run on the "
              "temperature thinned to a point per 5 s, which cuts every ramp corner (a known limitation, README: "
              "'What fails')."]
    L += ["", "## 3. Attribution (held-out, forward-chained)", "",
          "| effect | accepted | params | held-out gain [CI] | folds passed / can test | dBIC | gap before | after | shrink "
          "| why not |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for row in rep["ranked"]:
        ps = ", ".join(f"{k}={_fmt(v)}" for k, v in (row.get("params") or {}).items())
        ci = row.get("heldout_gain_ci")
        g = f"{_fmt(row.get('heldout_gain'))} [{_fmt(ci[0])}, {_fmt(ci[1])}]" if ci else "-"
        L.append(f"| {row['effect']} | {'**yes**' if row['accepted'] else 'no'} | {ps} | {g} | "
                 f"{_fmt(row.get('folds_passed'))} / {_fmt(row.get('folds_testable'))}{_undetermined(row)} | "
                 f"{_fmt(row.get('delta_bic'), '.3g')} | {_fmt(row.get('gap_before'))} | "
                 f"{_fmt(row.get('gap_after'))} | {_fmt(row.get('shrink'), '.3f')} | {'; '.join(row.get('why_not') or [])} |")
    if any(row.get("folds_undetermined") for row in rep["ranked"]):
        sd = rep.get("settings", {}).get("indeterminate_sd")
        L += ["", "A fold marked undetermined is one where the candidate's refit left its held-out prediction "
              f"uncertain by more than {_fmt(sd, 'g')} noise sigmas (a knob its parameter makes collinear on that "
              "training window): it tests one arbitrary point of that uncertainty, not the effect, and is left out "
              "of the candidate's held-out interval and fold counts."]
    held = [row for row in rep["ranked"] if row.get("held_knobs")]
    if held:
        L += ["", "Fitted with knobs held: " + "; ".join(f"{row['effect']} ({', '.join(row['held_knobs'])})" for row in held)
              + ". With every knob free its fit was refused at a physical bound; the record does not identify these "
              "knobs (calibration table), so the effect's amplitude can trade against them, and it was fitted again "
              "with them held at their calibrated values."]
    L += detection_lines(rep.get("detection_limits"), rep["accepted"])
    c = rep.get("combined")
    if c:
        L += ["", f"## 4. Gap before and after ({' + '.join(c['effects'])}), held-out data", "",
              "| metric | gap before | gap after | shrink |", "|---|---|---|---|"]
        for k, b in c["gap_before"].items():
            L.append(f"| {k} | {b:.4g} | {c['gap_after'].get(k, float('nan')):.4g} | {_fmt(c['shrink'].get(k), '.3f')} |")
    L += ["", "Gaps are the excess RMS over the null's noise, sqrt(max(0, MSE - noise)); shrink = 1 - G_after/G_before "
          "on the mean-square excess.", ""]
    return "\n".join(L)


def _coverage_lines(r: dict, settings: dict, design: dict | None = None) -> list[str]:
    """The folds' training and held-out temperatures, where the held-out data extrapolate, and what a record
    held at one temperature cannot identify (``design``, :func:`~.pipeline.design_check`), and whether what the
    model leaves lies after the last training window only (``design["gap_after_training"]``,
    :func:`~.windows.after_training_note`)."""
    folds = r.get("folds") or []
    if not folds or "train_C" not in folds[0]:
        return []
    not_scored, span_K = settings.get("folds_not_scored") or [], settings.get("min_train_span_K", 5.0)
    rng = lambda v: f"{v[0]:.1f} to {v[1]:.1f} C" if v else "-"  # noqa: E731
    L = ["| fold | trained on | tested on | held-out blocks outside the training range |", "|---|---|---|---|"]
    for k, f in enumerate(folds):
        n_rate = f.get("rate_blocks_unscored") or 0
        if k in not_scored and n_rate >= f["test_blocks"]:
            note = (" (not scored: every held-out block is a rate-table step and its training window holds no "
                    "applied rate)")
        elif k in not_scored:
            note = f" (not scored: its training window spans under {span_K:g} K)"
        elif n_rate:
            note = (f" ({n_rate} rate-table blocks not scored: no applied rate in its training window, so the scale "
                    "factor there is the prior's)")
        else:
            note = ""
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
    cj = clean(rep)
    atomic_write_text(out / "report.json", json.dumps(cj, indent=2) + "\n")
    atomic_write_text(out / "report.md", markdown(cj))
    return cj
