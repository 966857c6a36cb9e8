"""Two benchmark runs on the same stored cases, compared case by case.

A change to the diagnoser is best judged on the cases an earlier run already scored: each case is its own
control, so the comparison rests on the cases whose outcome changed (the discordant pairs of McNemar's test),
not on the difference of two rates each carrying its own sampling error. ``fmvmg diagnose-benchmark
--cases-from DIR`` re-diagnoses DIR's cases with the current code and, when DIR holds its scores, reports
:func:`paired_changes` beside the new scores.
"""

from __future__ import annotations

from scipy.stats import binomtest

#: Outcomes compared: (row key, cases it applies to, True when the outcome is the right one, label).
OUTCOMES = (
    ("false_alarm", lambda r: True, False, "null cases: no false alarm"),
    ("top1", lambda r: r["tier"] == "above", True, "single effects above the limit: top-1"),
    ("top2", lambda r: r["tier"] == "above", True, "single effects above the limit: top-2"),
    ("pair_exact", lambda r: True, True, "pairs: exact set"),
)


def paired_changes(before: list[dict], after: list[dict]) -> dict:
    """Outcomes that changed between two scorings of the same cases.

    Parameters
    ----------
    before, after : list of dict
        Per-case rows of :func:`.benchmark.score` (matched by ``case``; a case missing from either, or
        whose diagnosis failed in either, is left out).

    Returns
    -------
    dict
        By outcome key: ``label``, ``cases`` (compared), ``right_before``, ``right_after``, ``gained`` and
        ``lost`` (case numbers whose outcome turned right / wrong) and ``p_mcnemar`` (exact two-sided
        binomial test on the discordant cases; None when none changed).
    """
    prev = {r["case"]: r for r in before if r.get("error") is None}
    out = {}
    for key, sel, good, label in OUTCOMES:
        pairs = [(prev[r["case"]], r) for r in after
                 if r.get("error") is None and r["case"] in prev and key in r and key in prev[r["case"]] and sel(r)]
        ok_b = [bool(a[key]) == good for a, _ in pairs]
        ok_a = [bool(b[key]) == good for _, b in pairs]
        gained = [b["case"] for (_, b), x, y in zip(pairs, ok_b, ok_a) if y and not x]
        lost = [b["case"] for (_, b), x, y in zip(pairs, ok_b, ok_a) if x and not y]
        n_disc = len(gained) + len(lost)
        out[key] = {"label": label, "cases": len(pairs), "right_before": int(sum(ok_b)),
                    "right_after": int(sum(ok_a)), "gained": gained, "lost": lost,
                    "p_mcnemar": float(binomtest(len(gained), n_disc, 0.5).pvalue) if n_disc else None}
    return out


def format_paired(paired: dict, source: str) -> str:
    """Markdown table of :func:`paired_changes`.

    Parameters
    ----------
    paired : dict
    source : str
        Where the earlier run lies.

    Returns
    -------
    str
    """
    L = [f"## Against the earlier run on the same cases ({source})", "",
         "| outcome | cases | right before | right now | turned right | turned wrong | McNemar p |",
         "|---|---|---|---|---|---|---|"]
    for v in paired.values():
        p = "-" if v["p_mcnemar"] is None else f"{v['p_mcnemar']:.3g}"
        L.append(f"| {v['label']} | {v['cases']} | {v['right_before']} | {v['right_after']} | "
                 f"{', '.join(map(str, v['gained'])) or '-'} | {', '.join(map(str, v['lost'])) or '-'} | {p} |")
    return "\n".join(L) + "\n"
