"""Every compensator on every measured record, beside a bias calibration, a line in T and the noise floor.

Usage::

    python benchmarks/real_records.py [--data ../shared/data] [--methods M,...] [--json OUT.json] [--independent]

Each measured record is fitted on its first half in time and applied to its second half, and
the reverse; records of the same sensor and axis at temperatures that do not overlap (the
BMI270 cold and hot soaks) are also crossed. Prints a Markdown table of held-out RMS / RMS after
a bias calibration from the training part (1 = no better than a bias calibration; ``floor`` =
the record's white noise, which no drift model can remove), and the target check: the default
method (``poly-baseline``) against the better of a line in T and the selected polynomial
(:mod:`fmvmg_sim.validation.compensation_records`). Without ``--data`` it reads the shared data
folder beside the repository if there is one, else the copies in ``tests/data``. The
validation page (``python -m fmvmg_sim.validation.page``) carries the same table for the records in
``tests/data``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from tqdm import tqdm

REPO = Path(__file__).resolve().parents[1]


def default_data_dir() -> Path:
    """The shared data folder beside the repository, else the test copies."""
    for p in (REPO.parent / "shared" / "data", REPO.parent.parent / "shared" / "data"):
        if p.is_dir():
            return p
    return REPO / "tests" / "data"


def main(argv=None) -> int:
    from fmvmg_sim.validation import compensation_records as R

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None, help="shared data folder (default: see above)")
    ap.add_argument("--methods", default=",".join(R.METHODS), help="comma-separated methods")
    ap.add_argument("--json", type=Path, help="also write every figure to this JSON file")
    ap.add_argument("--independent", action="store_true",
                    help="also run on independent-dev, the records of an independent generator (slow: hours-long "
                         "records, every method)")
    a = ap.parse_args(argv)
    data = a.data or default_data_dir()
    methods = [m.strip() for m in a.methods.split(",") if m.strip()]
    records, skipped = R.load_records(data, independent=a.independent)
    cases = R.make_cases(records)
    t0 = time.perf_counter()
    for c in tqdm(cases, desc="real records", unit="case", file=sys.stderr):
        R.evaluate_case(c, methods)
    print(f"{len(records)} measured records in {data}, {len(cases)} train/test pairs, "
          f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    text = R.report(cases, skipped, methods)
    print(text)
    if a.json:
        a.json.write_text(json.dumps(R.to_dict(cases, skipped), indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
