"""Population-study speed on scenarios/population_oven.toml (oven_004's 13.1 h profile at 1 Hz, envelope engine).

Times one unit serially (its wall and CPU time: draw, envelope run, figures of merit), then a small population on
a LocalCluster with one worker per core, and prints units/s and the projection to 1,000 units against the
target of 600 s, beside the bound no scheduling can beat: per-unit CPU time x 1,000 / cores.

Usage: python benchmarks/population.py [--units 8] [--workers N] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmvmg_sim.population.study import run_population, run_unit  # noqa: E402
from fmvmg_sim.population.units import drawn_knobs  # noqa: E402
from fmvmg_sim.scenario import load_scenario  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: The target: 1,000 units in this many seconds.
TARGET_S = 600.0
TARGET_UNITS = 1000


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=8, help="units of the timed population (default 8)")
    ap.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: cores)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    cores = a.workers or os.cpu_count() or 1
    scn = load_scenario(REPO / "scenarios" / "population_oven.toml")
    knobs = drawn_knobs(scn)
    run_unit(load_scenario(REPO / "scenarios" / "population_oven.toml", ["scenario.duration_s=60"]), knobs, 0, 0)
    t0, c0 = time.perf_counter(), time.process_time()
    unit = run_unit(scn, knobs, 0, 0)
    serial_wall, serial_cpu = time.perf_counter() - t0, time.process_time() - c0
    pop = run_population(scn, a.units, seed=0, n_workers=cores, progress=not a.json)
    rate = a.units / pop.wall_time_s
    cpu_unit = float(sum(u["cpu_s"] for u in pop.units) / a.units)
    out = dict(units=a.units, workers=cores, serial_unit_wall_s=serial_wall, serial_unit_cpu_s=serial_cpu,
               cluster_wall_s=pop.wall_time_s, units_per_s=rate, cpu_s_per_unit_in_workers=cpu_unit,
               projected_1000_units_s=TARGET_UNITS / rate, bound_1000_units_s=cpu_unit * TARGET_UNITS / cores,
               target_s=TARGET_S, status=unit["status"])
    if a.json:
        print(json.dumps(out))
    else:
        print(f"one unit serially: {serial_wall:.2f} s wall, {serial_cpu:.2f} s CPU ({unit['status']})")
        print(f"{a.units} units on {pop.where}: {pop.wall_time_s:.1f} s, {rate:.3f} units/s, "
              f"{cpu_unit:.2f} s CPU per unit in the workers")
        print(f"1,000 units: projected {TARGET_UNITS / rate:.0f} s at this rate; bound (CPU per unit x 1,000 / "
              f"{cores} cores) {cpu_unit * TARGET_UNITS / cores:.0f} s; target {TARGET_S:.0f} s "
              f"({TARGET_UNITS / rate / TARGET_S:.1f} x the target)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
