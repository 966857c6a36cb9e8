"""Start-up cost of ``fmvmg --help``, ``fmvmg run --help`` and ``import fmvmg_sim``, against a bare interpreter.

Each command runs in a fresh interpreter, interleaved with the baseline (``python -c pass``) so that
the machine's load hits both alike; the figures are medians over the runs and the ratio is the
command's median over the baseline's. Target: ``fmvmg --help`` within 3x a bare interpreter (it was
about 50x while the CLI imported allantools, scipy and numpy to list its commands).

Usage: python benchmarks/cli_startup.py [--runs N] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time

CASES = {
    "baseline: python -c pass": ["-c", "pass"],
    "fmvmg --help": ["-m", "fmvmg_sim", "--help"],
    "fmvmg run --help": ["-m", "fmvmg_sim", "run", "--help"],
    "import fmvmg_sim": ["-c", "import fmvmg_sim"],
}


def _wall(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t0


def main() -> int:
    """Run the benchmark and print the table (or one JSON object).

    Returns
    -------
    int
        Exit code.
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=15)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    times: dict[str, list[float]] = {k: [] for k in CASES}
    for args in CASES.values():  # warm the file-system cache
        _wall(args)
    for _ in range(a.runs):
        for name, args in CASES.items():
            times[name].append(_wall(args))
    med = {k: statistics.median(v) for k, v in times.items()}
    base = med["baseline: python -c pass"]
    out = {k: {"median_s": round(v, 4), "ratio_to_baseline": round(v / base, 2)} for k, v in med.items()}
    if a.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:28s} {v['median_s'] * 1e3:8.1f} ms  {v['ratio_to_baseline']:6.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
