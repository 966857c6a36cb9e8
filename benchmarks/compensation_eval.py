"""Run the honest compensation comparison in method groups and merge the results.

Usage::

    python benchmarks/compensation_eval.py run GROUP OUTDIR [--seeds 5] [--quick]
    python benchmarks/compensation_eval.py merge OUTDIR DOCSDIR

``run`` evaluates one group of methods (``fast``: raw, line, poly-baseline, physics; ``vmd``:
vmd-wflp-cssvr; ``emd``: emd-rbf, emd-rbf-ga, emd-rbf-ga-kf; ``vmd-native``: vmd-wflp-cssvr
without decimation, the measured effect of the 100 Hz fix) and pickles the
:class:`~fmvmg_sim.validation.compensation_eval.Evaluation` to ``OUTDIR/GROUP.pkl``; ``merge`` combines
the groups found into ``DOCSDIR/compensation_eval.md``, the plots and the generated
blocks of ``DOCSDIR/compensation_results.md`` (every run, with what each method chose, into
``OUTDIR/compensation_eval.json``). Groups run one
after the other (the machine has 2 shared cores).

Budgets reduced for time (the settings are recorded in the JSON): the CS-SVR search of
vmd-wflp-cssvr uses 45 evaluations (15 nests x 3 generations) on at most 1,000 training
points instead of 1,515 on 2,000, the GA of emd-rbf-ga(-kf) 10 x 10
instead of 30 x 40.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import time
from pathlib import Path

GROUPS = {
    "fast": ["raw", "line", "poly-baseline", "physics"],
    "vmd": ["vmd-wflp-cssvr"],
    "emd": ["emd-rbf", "emd-rbf-ga", "emd-rbf-ga-kf"],
    "vmd-native": ["vmd-wflp-cssvr"],
}
PARAMS = {
    "fast": {},
    "vmd": {"vmd-wflp-cssvr": {"budget": 45, "n_max": 1000}},
    "emd": {"emd-rbf-ga": {"ga_population": 10, "ga_generations": 10},
            "emd-rbf-ga-kf": {"ga_population": 10, "ga_generations": 10}},
    "vmd-native": {"vmd-wflp-cssvr": {"budget": 45, "n_max": 1000, "decimate_Hz": None}},
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("group", choices=sorted(GROUPS))
    r.add_argument("outdir")
    r.add_argument("--seeds", type=int, default=5)
    r.add_argument("--quick", action="store_true")
    r.add_argument("--no-bandwidth", action="store_true")
    m = sub.add_parser("merge")
    m.add_argument("outdir")
    m.add_argument("docsdir")
    m.add_argument("--groups", default="fast,vmd,emd")
    a = ap.parse_args(argv)
    from fmvmg_sim.validation import compensation_eval as E
    from fmvmg_sim.validation.doc_blocks import replace_block
    if a.cmd == "run":
        t0 = time.perf_counter()
        ev = E.evaluate(GROUPS[a.group], seeds=a.seeds, quick=a.quick, method_params=PARAMS[a.group],
                        bandwidth=not a.no_bandwidth, progress=True)
        ev.config["group"] = a.group
        out = Path(a.outdir)
        out.mkdir(parents=True, exist_ok=True)
        with open(out / f"{a.group}.pkl", "wb") as fh:
            pickle.dump(ev, fh)
        (out / f"{a.group}.md").write_text(E.markdown_table(ev))
        (out / f"{a.group}.json").write_text(json.dumps(ev.to_dict(), indent=1))
        print(E.markdown_table(ev))
        print(f"wall {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        return 0
    out, docs = Path(a.outdir), Path(a.docsdir)
    evs = []
    for g in a.groups.split(","):
        p = out / f"{g}.pkl"
        if p.exists():
            with open(p, "rb") as fh:
                evs.append(pickle.load(fh))
        else:
            print(f"group {g}: no results in {p}", file=sys.stderr)
    ev = E.merge(evs)
    order = [m for m in E.ALL_METHODS if m in ev.summary] + [m for m in ev.summary if m not in E.ALL_METHODS]
    ev.summary = {m: ev.summary[m] for m in order}
    ev.config["methods"] = order
    docs.mkdir(parents=True, exist_ok=True)
    (docs / "compensation_eval.md").write_text(E.markdown_table(ev))
    (out / "compensation_eval.json").write_text(json.dumps(ev.to_dict(), indent=1))  # every run, beside the runs
    E.plot_allan(ev, docs / "compensation_allan.png")
    E.plot_traces(ev, docs / "compensation_traces.png")
    E.plot_summary(ev, docs / "compensation_summary.png")
    page = docs / "compensation_results.md"
    if page.is_file():
        replace_block(page, "compensate-eval", E.markdown_table(ev))
        replace_block(page, "papers", E.papers_table(ev))
        print(f"wrote the compensate-eval and papers blocks of {page}", file=sys.stderr)
    print(E.markdown_table(ev))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
