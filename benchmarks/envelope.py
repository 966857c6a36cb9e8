"""Envelope-engine speed on paper 004's oven profile (~13 h simulated at 100 Hz output, noise on).

Prints the wall time of the averaged model for the whole scenario beside the carrier engine's cost for the
same simulated time, extrapolated from a short carrier run of the same device in the same process.

Usage: python benchmarks/envelope.py [--json] [--carrier-sample-s 0.5]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmvmg_sim.carrier.engine import run_carrier  # noqa: E402
from fmvmg_sim.envelope.engine import run_envelope  # noqa: E402
from fmvmg_sim.scenario import load_scenario  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--carrier-sample-s", type=float, default=0.5)
    a = ap.parse_args()
    path = REPO / "scenarios" / "oven_004.toml"
    scn = load_scenario(path, fidelity="envelope")
    run_envelope(load_scenario(path, fidelity="envelope", overrides=["scenario.duration_s=10"]), progress=False)
    t0 = time.perf_counter()
    res = run_envelope(scn, progress=not a.json)
    wall = time.perf_counter() - t0
    short = load_scenario(path, fidelity="carrier",
                          overrides=[f"scenario.duration_s={a.carrier_sample_s}", "scenario.output_rate_Hz=100"])
    run_carrier(load_scenario(path, fidelity="carrier", overrides=["scenario.duration_s=0.01"]), progress=False)
    t0 = time.perf_counter()
    rc = run_carrier(short, progress=False)
    per_s = (time.perf_counter() - t0) / rc.info["simulated_time_s"]
    sim = res.info["simulated_time_s"]
    out = dict(wall_s=wall, simulated_s=sim, carrier_estimate_s=per_s * sim, carrier_s_per_sim_s=per_s,
               speedup=per_s * sim / wall, samples=len(res.time_s), target_wall_s=20.0)
    if a.json:
        print(json.dumps(out))
    else:
        print(f"envelope: {sim / 3600:.2f} h simulated at 100 Hz in {wall:.1f} s wall (target <= 20 s)")
        print(f"carrier engine for the same: ~{per_s * sim / 60:.0f} min ({per_s:.3f} s per simulated s); "
              f"speed-up {out['speedup']:.0f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
