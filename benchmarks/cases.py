"""Benchmark case generation: CPU per labelled case, with the Fitters of a case sharing their response tables.

``diagnose-benchmark`` spends about half of a run making its cases: each case is simulated, then its
signature SNR is computed several times (the amplitude search, the whole record, the training window, a
pair's members), and each SNR calibrates the nominal knobs afresh on records of the same profile. Those
calibrations share their response tables (``cases.make_case``). The named baseline is the
same code with every Fitter on its own tables (``cases._make_case`` called outside ``make_case``'s store).
Both make the same cases, in separate directories; the labels and records must be identical, bit for bit.

Usage: python benchmarks/cases.py [--cases N] [--seed S] [--mix single|default|pair] [--json]
"""

from __future__ import annotations

import argparse
import filecmp
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmvmg_sim.validation import cases  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
MIXES = {"single": cases.CaseMix(p_null=0.0, p_single=1.0), "default": cases.CaseMix(),
         "pair": cases.CaseMix(p_null=0.0, p_single=0.0)}


def _timed(make, k: int, seed: int, out: Path, mix) -> float:
    t = time.process_time()
    make(k, seed, out, str(REPO / "scenarios" / "nominal_a.toml"), 3 * 3600.0, 1.0, mix)
    return time.process_time() - t


def _same(a: Path, b: Path, k: int) -> bool:
    la = json.loads((a / "labels" / f"case_{k:04d}.json").read_text())
    lb = json.loads((b / "labels" / f"case_{k:04d}.json").read_text())
    la.pop("record")
    lb.pop("record")
    return la == lb and filecmp.cmp(a / "cases" / f"case_{k:04d}.csv", b / "cases" / f"case_{k:04d}.csv",
                                    shallow=False)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=4)
    ap.add_argument("--seed", type=int, default=4711)
    ap.add_argument("--mix", choices=sorted(MIXES), default="single")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    mix = MIXES[a.mix]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        shared, own = Path(tmp) / "shared", Path(tmp) / "own"
        _timed(cases.make_case, a.cases, a.seed, Path(tmp) / "warm-up", mix)  # imports and compiled code loaded
        for k in range(a.cases):
            t_own = _timed(cases._make_case, k, a.seed, own, mix)
            t_shared = _timed(cases.make_case, k, a.seed, shared, mix)
            rows.append({"case": k, "cpu_own_tables_s": t_own, "cpu_shared_tables_s": t_shared,
                         "identical": _same(own, shared, k)})
            if not a.json:
                print(f"case {k}: own tables {t_own:.2f} s CPU, shared {t_shared:.2f} s "
                      f"({t_shared / t_own:.2f}x), identical: {rows[-1]['identical']}", flush=True)
    tot_own = sum(r["cpu_own_tables_s"] for r in rows)
    tot_shared = sum(r["cpu_shared_tables_s"] for r in rows)
    res = {"seed": a.seed, "mix": a.mix, "cases": rows, "cpu_own_tables_s": tot_own,
           "cpu_shared_tables_s": tot_shared, "ratio_shared_to_own": tot_shared / tot_own,
           "all_identical": all(r["identical"] for r in rows)}
    if a.json:
        print(json.dumps(res, indent=1))
    else:
        print(f"{a.cases} cases ({a.mix}, seed {a.seed}): {tot_shared:.1f} s CPU against {tot_own:.1f} s with each "
              f"Fitter on its own tables (ratio {res['ratio_shared_to_own']:.2f}); identical: {res['all_identical']}")
    return 0 if res["all_identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
