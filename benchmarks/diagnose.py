"""Diagnosis speed: a 13 h oven record at 10 Hz, the whole effect library, on this machine (target <= 3 min).

Simulates paper 004's oven profile (about 13 h) with one effect withheld (thermal lag, tau 600 s) at
10 Hz with the envelope engine, writes it as a record, then times ``diagnose`` on it with the nominal
scenario (calibration, 6 null re-simulations, all 13 effects, forward selection of a second).

The CPU time of the diagnosis is printed beside the wall time: on a machine busy with other work
the wall time grows and the CPU time hardly does.

Usage: python benchmarks/diagnose.py [--json] [--null-runs N]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmvmg_sim.diagnosis.pipeline import N_NULL, diagnose  # noqa: E402
from fmvmg_sim.envelope.engine import run_envelope  # noqa: E402
from fmvmg_sim.record import write_record  # noqa: E402
from fmvmg_sim.scenario import load_scenario  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
TARGET_S = 180.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--null-runs", type=int, default=N_NULL)
    a = ap.parse_args()
    scn = load_scenario(REPO / "scenarios" / "oven_004.toml",
                        ["scenario.output_rate_Hz=10", "effects.thermal_lag.tau_s=600", "effects.thermal_lag.offset_K=0.3"],
                        seed=3)
    t0 = time.perf_counter()
    res = run_envelope(scn, progress=False)
    sim_s = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as d:
        rec = Path(d) / "oven_004_10Hz.csv"
        write_record(rec, res.to_record())
        t0, c0 = time.perf_counter(), time.process_time()
        rep = diagnose(rec, REPO / "scenarios" / "nominal_a.toml", n_null=a.null_runs, progress=not a.json)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    out = {"record_hours": float(res.time_s[-1] / 3600), "samples": int(len(res.time_s)), "rate_Hz": 10.0,
           "simulate_s": sim_s, "diagnose_s": wall, "diagnose_cpu_s": cpu, "target_s": TARGET_S,
           "within_target": wall <= TARGET_S,
           "verdict": rep["verdict"], "accepted": rep["accepted"], "null_runs": a.null_runs,
           "cpu_cores": __import__("os").cpu_count()}
    if a.json:
        sys.stdout.write(json.dumps(out) + "\n")
    else:
        print(f"diagnose: {out['record_hours']:.1f} h record at 10 Hz ({out['samples']} samples): "
              f"{wall:.1f} s (CPU {cpu:.1f} s; target {TARGET_S:.0f} s, ratio {wall / TARGET_S:.2f}) "
              f"-> verdict {rep['verdict']} {rep['accepted']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
