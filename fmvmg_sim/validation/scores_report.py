"""The benchmark's scores as a page a person reads: targets against measured values, tiers, misses by cause.

Reads only the scores object of :func:`~.scoring.score` (plus the run settings :func:`~.benchmark.run_benchmark`
adds); knows nothing of how the cases were made or diagnosed.
"""

from __future__ import annotations

from .scoring import IMPOSSIBLE_CAUSES, MISS_CAUSES

#: The issue's targets: (score key, count key, comparison, target, label).
TARGETS = (
    ("false_alarm_rate", "null_cases", "<=", 0.05, "false alarms (null cases)"),
    ("top1", "single_above", ">=", 0.90, "top-1, single effects above the limit"),
    ("top2", "single_above", ">=", 0.98, "top-2, single effects above the limit"),
    ("pairs_exact", "pair_cases", ">=", 0.70, "exact pairs"),
    ("median_shrink", None, ">=", 0.80, "median held-out shrink when right"),
)


def _pct(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def _count(v, n) -> str:
    """``k of n`` from a rate and its denominator (rates are means of booleans)."""
    if v is None or n is None:
        return "-"
    return f"{round(v * n)} of {n}"


def _interval(ci) -> str:
    return "-" if not ci else f"{ci[0]:.3f}-{ci[1]:.3f}"


def _met(v, ci, op: str, target: float) -> str:
    """Whether a target is met by the point value; "(decided)" when the 95 % interval lies on one side of it."""
    if v is None:
        return "-"
    met = v <= target if op == "<=" else v >= target
    out = "yes" if met else "no"
    if ci and (ci[1] < target or ci[0] > target):
        out += " (decided)"
    return out


def targets_table(sc: dict) -> list[str]:
    """The scores against their :data:`TARGETS`: measured, counts, Wilson 95 % interval, target, whether met.

    Parameters
    ----------
    sc : dict
        From :func:`~.scoring.score`.

    Returns
    -------
    list of str
        Markdown table lines.
    """
    cis = sc.get("ci95") or {}
    L = ["| score | measured | cases | 95 % interval | target | met |", "|---|---|---|---|---|---|"]
    for key, nkey, op, target, label in TARGETS:
        v = sc.get(key)
        n = sc.get(nkey) if nkey else None
        L.append(f"| {label} | {_pct(v)} | {_count(v, n) if nkey else '-'} | {_interval(cis.get(key))} | "
                 f"{op} {target:g} | {_met(v, cis.get(key), op, target)} |")
    return L


def format_scores(sc: dict) -> str:
    """Markdown summary of benchmark scores.

    Parameters
    ----------
    sc : dict
        From :func:`~.scoring.score` (``seed``, ``null_runs`` and ``mix`` are used when present).

    Returns
    -------
    str
    """
    head = f"# Diagnosis benchmark: {sc['cases']} cases"
    if "seed" in sc:
        head += f", seed {sc['seed']}"
    if "cases_from" in sc:
        head += f", stored in {sc['cases_from']}"
    L = [head, ""]
    if sc.get("errors"):
        L += [f"**{sc['errors']} diagnoses failed** (scored as misses; their rows hold the error).", ""]
    L += targets_table(sc)
    L += ["", "Intervals: Wilson score, 95 %, on the counted cases; \"decided\" when the whole interval lies on one "
          "side of the target."]
    ceil = sc.get("ceiling") or {}
    if any((ceil.get(k) or {}).get("cases") for k in ceil):
        L += ["", "How far any diagnosis could go on these cases under the forward-chained protocol: each score with every "
              "miss put right but those whose cause the record or the protocol forbids (" +
              ", ".join(f"`{c}`" for c in IMPOSSIBLE_CAUSES) + "); an upper bound:", "",
              "| score | measured | ceiling | cases | 95 % interval | target | target within reach |",
              "|---|---|---|---|---|---|---|"]
        for key, nkey, op, target, label in TARGETS:
            d = ceil.get(key) or {}
            if d.get("cases"):
                L.append(f"| ceiling, {label} | {_pct(sc.get(key))} | {_pct(d['rate'])} | {d['reachable']} of {d['cases']} | "
                         f"{_interval(d['ci95'])} | {op} {target:g} | {_met(d['rate'], d['ci95'], op, target)} |")
    L += ["", "| other score | measured | cases |", "|---|---|---|",
          f"| exact pairs, both members above the limit | {_pct(sc.get('pairs_exact_above'))} | "
          f"{_count(sc.get('pairs_exact_above'), sc.get('pair_cases_above'))} |",
          f"| exact pairs, both members above the limit beside the other (separable) | "
          f"{_pct(sc.get('pairs_exact_separable'))} | "
          f"{_count(sc.get('pairs_exact_separable'), sc.get('pair_cases_separable'))} |",
          f"| truth in the ambiguity set (above the limit) | {_pct(sc.get('truth_in_ambiguity_set'))} | - |",
          f"| right, but a located gap left open | {_pct(sc.get('partial_when_right'))} | "
          f"{_count(sc.get('partial_when_right'), sc.get('right_cases'))} |",
          f"| median relative parameter error when right | {_pct(sc.get('param_rel_error_median'))} | - |"]
    if sc.get("ool_cases"):
        L += [f"| out of library: \"unexplained\" (above the limit) | {_pct(sc.get('ool_unexplained_rate_above'))} | "
              f"{sc.get('ool_cases_above')} |",
              f"| out of library: confidently mis-attributed (above) | {_pct(sc.get('ool_confident_rate_above'))} | "
              f"{sc.get('ool_cases_above')} |"]
    tiers = sc.get("by_tier") or {}
    if tiers:
        L += ["", "By SNR tier (a pair by its weaker member):", "",
              "| tier | single cases | top-1 | top-2 | pair cases | exact pairs |", "|---|---|---|---|---|---|"]
        for t in ("above", "near", "below"):
            d = tiers.get(t) or {}
            L.append(f"| {t} | {d.get('single_cases', 0)} | {_pct(d.get('top1'))} | {_pct(d.get('top2'))} | "
                     f"{d.get('pair_cases', 0)} | {_pct(d.get('pairs_exact'))} |")
    bands = [b for b in sc.get("above_by_snr") or () if b.get("single_cases")]
    if bands:
        L += ["", "Single effects above the limit by signature SNR (95 % intervals):", "",
              "| SNR | cases | top-1 | top-2 |", "|---|---|---|---|"]
        for b in bands:
            lo, hi = b["snr_min"], b["snr_max"]
            snr = f">= {lo:g}" if hi is None else (f"< {hi:g}" if lo == 0 else f"{lo:g}-{hi:g}")
            L.append(f"| {snr} | {b['single_cases']} | {_pct(b['top1'])} ({_interval(b['top1_ci95'])}) | "
                     f"{_pct(b['top2'])} ({_interval(b['top2_ci95'])}) |")
    tw = sc.get("training_window_tiers") or {}
    if any((tw.get(k) or {}).get("single_cases") for k in ("train_above", "train_below")):
        L += ["", "Single effects above the limit by what the diagnoser's training window carries of them (a "
              "diagnostic beside the target, whose limit is the whole record's; 95 % intervals):", "",
              "| training window | cases | top-1 | top-2 |", "|---|---|---|---|"]
        for k, label in (("train_above", "above the limit there too"), ("train_below", "below the limit there")):
            d = tw.get(k) or {}
            if d.get("single_cases"):
                L.append(f"| {label} | {d['single_cases']} | {_pct(d['top1'])} ({_interval(d['top1_ci95'])}) | "
                         f"{_pct(d['top2'])} ({_interval(d['top2_ci95'])}) |")
    note = sc.get("after_training_note") or {}
    if any((note.get(k) or {}).get("cases") for k in note):
        L += ["", "How often the report's record-design note (a gap after the last training window only) fired:", "",
              "| cases | fired |", "|---|---|"]
        for k, label in (("miss_train_below", "top-2 misses above the limit, training window below it"),
                         ("miss_train_above", "top-2 misses above the limit, training window above it"),
                         ("hit", "top-2 hits above the limit"), ("null", "null cases")):
            d = note.get(k) or {}
            if d.get("cases"):
                L.append(f"| {label} | {d['fired']} of {d['cases']} |")
    dc = sc.get("detection_claim") or {}
    if dc.get("bands"):
        L += ["", "Do the reports' detection limits hold? Each report gives, per effect, the size it would attribute "
              f"with probability {dc['power']}; single effects by their true size over their report's limit (found: "
              "accepted or in an ambiguity set; 95 % intervals):", "",
              "| size / limit | cases | found | top-2 |", "|---|---|---|---|"]
        bands = [(f">= {b['ratio_min']:g}" if b["ratio_max"] is None else f"{b['ratio_min']:g}-{b['ratio_max']:g}", b)
                 for b in dc["bands"]]
        for lab, d in [(">= 1 (the claim)", dc["above"]), ("< 1", dc["below"])] + bands:
            if d["cases"]:
                L.append(f"| {lab} | {d['cases']} | {d['found'] / d['cases']:.3f} ({_interval(d['found_ci95'])}) | "
                         f"{d['top2'] / d['cases']:.3f} ({_interval(d['top2_ci95'])}) |")
    causes = sc.get("misses_by_cause") or {}
    if causes:
        rows = {k: [causes.get(g, {}).get(k, 0) for g in ("single_above", "pairs_above", "pairs")] for k in MISS_CAUSES}
        rows = {k: v for k, v in rows.items() if any(v)}
        L += ["", "Why true effects were missed (each missing member of a missed case):", ""]
        if rows:
            L += ["| cause | single effects above | pairs above | pairs, all |", "|---|---|---|---|"]
            L += [f"| {k}: {MISS_CAUSES[k]} | {v[0]} | {v[1]} | {v[2]} |" for k, v in rows.items()]
        else:
            L.append("No single effect above the limit and no pair member was missed.")
    return "\n".join(L) + "\n"
