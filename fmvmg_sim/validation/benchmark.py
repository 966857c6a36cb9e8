"""``fmvmg diagnose-benchmark``: generate labelled cases, diagnose them on Dask, score against the labels.

The diagnoser sees only each case's record and the nominal scenario; the labels are read back by the scorer
(:mod:`.scoring`) after every diagnosis has returned.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

from ..diagnosis.pipeline import N_NULL, diagnose
from ..diagnosis.report import write_report
from ..record import atomic_write_text
from .cases import CaseMix, make_case
from .paired import format_paired, paired_changes
from .scores_report import format_scores
from .scoring import answer_snr, score, wrong_answer


def _diagnose_case(record: str, scenario: str, n_null: int, out_dir: str) -> dict:
    """Worker: diagnose one record (the only inputs: the record and the nominal scenario)."""
    warnings.simplefilter("ignore")
    try:
        rep = diagnose(record, scenario, n_null=n_null, progress=False, log=lambda m: None)
    except Exception as exc:  # a failed diagnosis is scored as a failure, not hidden
        return {"record": record, "error": f"{type(exc).__name__}: {exc}"}
    cj = write_report(rep, Path(out_dir))
    return {"record": record, "verdict": cj["verdict"], "accepted": cj["accepted"],
            "ambiguous_with": cj["ambiguous_with"], "ranked": [r["effect"] for r in cj["ranked"]],
            "rows": {r["effect"]: {"params": r.get("params"), "shrink": r.get("shrink"), "accepted": r["accepted"],
                                   "folds_testable": r.get("folds_testable"), "why_not": r.get("why_not")}
                     for r in cj["ranked"]},
            "combined": cj.get("combined"), "design": cj.get("design"),
            "detection_limits": cj.get("detection_limits"), "wall_time_s": cj["wall_time_s"]}


def _make(k, seed, out, scenario, duration_s, rate_Hz, mix=None):
    return make_case(k, seed, Path(out), scenario, duration_s, rate_Hz, mix)


def run_benchmark(n_cases: int, seed: int, out: Path, scenario: str, scheduler: str | None = None,
                  duration_s: float = 3 * 3600.0, rate_Hz: float = 1.0, n_null: int = N_NULL,
                  n_workers: int = 2, progress: bool = True, mix=None, cases_from: Path | None = None) -> dict:
    """Generate, diagnose (on Dask) and score ``n_cases`` cases.

    Parameters
    ----------
    n_cases, seed : int
    out : Path
    scenario : str
        Nominal scenario.
    scheduler : str, optional
        Address of an existing Dask scheduler; default a LocalCluster.
    duration_s, rate_Hz : float, optional
        Case records.
    n_null : int, optional
        Null re-simulations per diagnosis: by default the diagnosis' own (:data:`~fmvmg_sim.diagnosis.null.N_NULL`),
        so that the scores are those of the diagnosis a user runs. Fewer replicates estimate the null's spread
        more poorly and raise the false alarms.
    n_workers : int, optional
    progress : bool, optional
    mix : CaseMix, optional
        What the cases are drawn from (default: the issue's mix).
    cases_from : Path, optional
        An earlier run's folder: its stored cases and labels are diagnosed again with the current code
        (nothing is generated; ``n_cases``, ``seed``, ``duration_s``, ``rate_Hz`` and ``mix`` are not used),
        and, when it holds its scores, the outcomes are compared case by case (:func:`.paired.paired_changes`,
        ``paired`` in the scores).

    Returns
    -------
    dict
        The scores.
    """
    from dask.distributed import Client, LocalCluster, as_completed
    from tqdm import tqdm
    out.mkdir(parents=True, exist_ok=True)
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    label_dir = (cases_from or out) / "labels"
    try:
        if cases_from is None:
            futs = client.map(_make, range(n_cases), seed=seed, out=str(out), scenario=str(scenario),
                              duration_s=duration_s, rate_Hz=rate_Hz, mix=mix, pure=False)
            recs = []
            for f in tqdm(as_completed(futs), total=n_cases, disable=not progress, file=sys.stderr, desc="cases"):
                recs.append(f.result()["record"])  # the label itself stays on disk until scoring
            recs = sorted(recs)
        else:
            recs = stored_cases(cases_from)
        dfuts = [client.submit(_diagnose_case, r, str(scenario), n_null, str(out / "reports" / Path(r).stem),
                               pure=False) for r in recs]
        for _ in tqdm(as_completed(dfuts), total=len(dfuts), disable=not progress, file=sys.stderr, desc="diagnoses"):
            pass
        results = [f.result() for f in dfuts]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    labels = [json.loads((label_dir / f"{Path(r).stem}.json").read_text()) for r in recs]
    # how far each wrong answer is from the truth in the record's own noise (read after every diagnosis)
    missed = [k for k, (lab, res) in enumerate(zip(labels, results)) if wrong_answer(lab, res)]
    for k in tqdm(missed, disable=not progress, file=sys.stderr, desc="misses"):
        results[k]["snr_truth_beyond_answer"] = answer_snr(labels[k], results[k], str(scenario))
    sc = score(labels, results)
    if cases_from is None:
        sc.update(seed=seed, case_duration_s=duration_s, case_rate_Hz=rate_Hz, null_runs=n_null,
                  mix=(mix or CaseMix()).as_dict())
    else:
        sc.update(cases_from=str(cases_from), null_runs=n_null)
        before = cases_from / "scores.json"
        if before.is_file():
            earlier = json.loads(before.read_text())
            sc["paired"] = paired_changes(earlier["rows"], sc["rows"])
            # what made the cases (their seed, length, rate and mix) is the earlier run's
            sc.update({k: earlier[k] for k in ("seed", "case_duration_s", "case_rate_Hz", "mix") if k in earlier})
    md = format_scores(sc)
    if "paired" in sc:
        md += "\n" + format_paired(sc["paired"], str(cases_from))
    atomic_write_text(out / "scores.json", json.dumps(sc, indent=1, default=float) + "\n")
    atomic_write_text(out / "scores.md", md)
    return sc


def stored_cases(folder: Path) -> list[str]:
    """The records of an earlier benchmark run, each with its label.

    Parameters
    ----------
    folder : Path
        The run's output folder (``cases/case_*.csv`` and ``labels/case_*.json``).

    Returns
    -------
    list of str
        Record paths, sorted.

    Raises
    ------
    ValueError
        No stored case, a case without its label, a label or ``scores.json`` that is not one (the message
        names the file).
    """
    recs = sorted(str(p) for p in (folder / "cases").glob("case_*.csv"))
    if not recs:
        raise ValueError(f"no stored case (cases/case_*.csv) in {folder}")
    for r in recs:
        lab = folder / "labels" / f"{Path(r).stem}.json"
        if not lab.is_file():
            raise ValueError(f"{r} has no label ({lab})")
        try:
            keys = json.loads(lab.read_text())
        except (ValueError, UnicodeDecodeError) as exc:
            raise ValueError(f"{lab}: not JSON ({exc})") from None
        missing = [k for k in ("case", "effects", "tier", "snr") if not isinstance(keys, dict) or k not in keys]
        if missing:
            raise ValueError(f"{lab}: not a benchmark label (missing {', '.join(missing)})")
    scores = folder / "scores.json"
    if scores.is_file():
        try:
            rows = json.loads(scores.read_text()).get("rows")
        except (ValueError, UnicodeDecodeError, AttributeError) as exc:
            raise ValueError(f"{scores}: not the scores of a benchmark run ({exc})") from None
        if not isinstance(rows, list):
            raise ValueError(f"{scores}: not the scores of a benchmark run (no per-case rows)")
    return recs
