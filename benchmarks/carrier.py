"""Carrier-engine speed: wall seconds per simulated second for the full config-A diagram.

Ours: the compiled step function (all blocks, noise on) at 32 steps per drive cycle.
Baseline (named): scipy ``solve_ivp`` (LSODA) on the same right-hand side, i.e. the
same linear core (continuous-time matrices of the same diagram), rectifier, PI,
carrier normaliser and demodulators, written as a numpy function; noise off for the
baseline (an adaptive solver cannot integrate white noise), which only flatters it.
Both run in this process on the same machine; the ratio is what counts.

Wall time is the figure that counts; CPU (process) time is printed beside it because on a shared machine the
wall time includes the time the process waited for a core.

Usage: python benchmarks/carrier.py [--json] [--sim-s 1.0] [--baseline-sim-s 0.01]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmvmg_sim.averaged import steady_state  # noqa: E402
from fmvmg_sim.carrier.step import CARRIER_MODEL  # noqa: E402
from fmvmg_sim.compiled import cache_dir, load_rollout  # noqa: E402
from fmvmg_sim.carrier.engine import run_carrier  # noqa: E402
from fmvmg_sim.diagram import build_diagram  # noqa: E402
from fmvmg_sim.scenario import load_scenario  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def scenario(sim_s: float, spc: int):
    return load_scenario(REPO / "scenarios" / "startup.toml",
                         overrides=[f"scenario.duration_s={sim_s}", f"scenario.steps_per_cycle={spc}",
                                    "scenario.output_rate_Hz=1000", "initial.state=\"steady\""])


def baseline_rhs(dg):
    """The diagram's continuous-time right-hand side (numpy), for solve_ivp."""
    ss = steady_state(dg)
    g0 = ss.modulator_gain
    S = dg.core_state_scale()
    c0, cg = dg.core_system(g0), dg.core_system(g0 + 1.0)
    A0 = (1 / S)[:, None] * np.asarray(c0.A) * S[None, :]
    Ag = (1 / S)[:, None] * (np.asarray(cg.A) - np.asarray(c0.A)) * S[None, :]
    C = np.asarray(c0.C) * S[None, :]
    la = dg.amplitude_lpf.linear_model()
    lo = dg.output_lpf.linear_model()
    Aa, Ba = np.asarray(la.A), np.asarray(la.B)[:, 0]
    Ao, Bo = np.asarray(lo.A), np.asarray(lo.B)[:, 0]
    Gfx = (1 / S) * np.asarray(c0.B)[:, 0]
    kp, ki, umax = dg.pi.kp, dg.pi.ki_per_s, dg.pi.u_max_V
    vdac, kmod, km = dg.vdac_V, dg.modulator.k_per_V, dg.demodulator.k_per_V
    cr, sr = np.cos(dg.phase_trim_rad), np.sin(dg.phase_trim_rad)
    floor = 0.1 * ss.v_ps_amplitude_V
    qc, vdc2 = dg.comb_drive.quadratic_coef_N_per_V2, dg.comb_drive.vdc_V ** 2

    def f(t, y):
        z, sa, integ, si, sq = y[:8], y[8:10], y[10], y[11:13], y[13:15]
        vx, vps, vs = C[0] @ z, C[1] @ z, C[2] @ z
        n = vdac / max(np.hypot(vx, vps), floor)
        e = dg.vref_V - sa[0]
        u = min(max(kp * e + ki * integ, 0.0), umax)
        g = kmod * u * n
        vac = g * vps
        dz = A0 @ z + (g - g0) * (Ag @ z) + Gfx * qc * (vdc2 + vac * vac)
        dsa = Aa @ sa + Ba * abs(vps)
        dint = e
        ri, rq = n * (cr * vps - sr * vx), n * (cr * vx + sr * vps)
        dsi = Ao @ si + Bo * km * vs * ri
        dsq = Ao @ sq + Bo * km * vs * rq
        return np.concatenate([dz, dsa, [dint], dsi, dsq])

    y0 = np.zeros(15)
    y0[0] = ss.amplitude_m / S[0]
    y0[8] = dg.vref_V
    y0[10] = ss.agc_effort_V / ki
    return f, y0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--sim-s", type=float, default=1.0, help="simulated seconds for the compiled engine")
    ap.add_argument("--baseline-sim-s", type=float, default=0.01, help="simulated seconds for solve_ivp")
    ap.add_argument("--steps-per-cycle", type=int, default=32)
    a = ap.parse_args()
    # first-run compile time (fresh cache name by clearing the library if asked) and cached load
    t0 = time.perf_counter()
    roll = load_rollout(CARRIER_MODEL, log=lambda m: None)
    load_s = time.perf_counter() - t0
    scn = scenario(a.sim_s, a.steps_per_cycle)
    run_carrier(scenario(0.01, a.steps_per_cycle), progress=False)  # warm caches (plans, library)
    t0, c0 = time.perf_counter(), time.process_time()
    res = run_carrier(scn, progress=False)
    ours = (time.perf_counter() - t0) / res.info["simulated_time_s"]
    ours_cpu = (time.process_time() - c0) / res.info["simulated_time_s"]
    dg = build_diagram(scn.device, 25.0)
    f, y0 = baseline_rhs(dg)
    t0 = time.perf_counter()
    sol = solve_ivp(f, (0, a.baseline_sim_s), y0, method="LSODA", rtol=1e-8, atol=1e-10, max_step=1e-5)
    base = (time.perf_counter() - t0) / a.baseline_sim_s
    out = dict(s_per_sim_s=ours, cpu_s_per_sim_s=ours_cpu, baseline_s_per_sim_s=base, ratio=base / ours, steps_per_cycle=a.steps_per_cycle,
               baseline="scipy solve_ivp LSODA (rtol 1e-8), same right-hand side, noise off",
               compiled=roll.compiled, library_load_s=load_s, baseline_ok=bool(sol.success),
               ns_per_step=ours / (a.steps_per_cycle * dg.resonator.f_drive_Hz) * 1e9, cache=str(cache_dir()))
    if a.json:
        print(json.dumps(out))
    else:
        print(f"compiled carrier engine: {ours:.3f} s per simulated s wall, {ours_cpu:.3f} s CPU "
              f"({out['ns_per_step']:.0f} ns/step, {a.steps_per_cycle} steps/cycle, noise on)")
        print(f"solve_ivp LSODA baseline: {base:.1f} s per simulated s")
        print(f"ratio: {base / ours:.0f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
