"""Carrier-engine speed against the plain-C limit: the full config-A diagram, noise on, 32 steps per cycle.

Baseline (named): the plain-C reference loop of the physics brief's tool survey
(``shared/reference/peers.md``): a 9-state closed drive/sense loop (two modes, Coriolis
and quadrature coupling, pickoff, first-order-lag 90-degree shifter, full-wave rectifier
and low-pass amplitude estimate, PI amplitude control, modulated drive force, demodulator
and 2nd-order Butterworth rate output) integrated by RK4 at the same step, written as one
C function and compiled with ``gcc -O2``: what a hand-written simulator costs at best.
It is a smaller model than ours (9 states, no noise, no exact discretisation); the figure
says what the whole diagram costs on top of that limit.

Ours, measured in the same process, interleaved with the reference, best of ``--reps``:

* ``roll-out``: the compiled roll-out alone (per step, noise drawn in the compiled code);
* ``run``: ``run_carrier`` end to end for ``--sim-s`` simulated seconds (inputs, roll-out,
  record channels), operating points cached from an earlier run in the process;
* ``first run``: the same with the operating point built (the cost of a new temperature);
* ``--units N``: ``run_carrier_units`` on N units of different tolerances and seeds, per unit.

Wall-clock ratios from one run count; CPU (thread) time is printed beside them because on
a shared machine wall time includes waiting for a core.

Usage: python benchmarks/carrier.py [--sim-s 1] [--reps 5] [--units 1,4,8] [--json] [--solve-ivp]
"""

from __future__ import annotations

import argparse
import ctypes
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmvmg_sim.averaged import steady_state  # noqa: E402
from fmvmg_sim.carrier import engine  # noqa: E402
from fmvmg_sim.carrier.engine import run_carrier, run_carrier_units  # noqa: E402
from fmvmg_sim.carrier.plan import initial_state, make_plan  # noqa: E402
from fmvmg_sim.carrier.step import CARRIER_MODEL  # noqa: E402
from fmvmg_sim.compiled import cache_dir, load_rollout  # noqa: E402
from fmvmg_sim.diagram import build_diagram  # noqa: E402
from fmvmg_sim.scenario import load_scenario  # noqa: E402

REPO = Path(__file__).resolve().parents[1]

REFERENCE_C = r"""
#include <math.h>
#include <string.h>
typedef struct { double wd, ws, Qd, Qs, rate, kq, kpick, wl, gps, wa, vref, kp, ki, umax, kf, wo, h; } refp;
static inline void rhs(const double* s, double* d, const refp* p) {
  double x = s[0], v = s[1], y = s[2], w = s[3], ps = s[4], a = s[5], I = s[6], o1 = s[7], o2 = s[8];
  double vx = p->kpick * x, vs = p->kpick * y;
  double e = p->vref - a;
  double u = p->kp * e + p->ki * I;
  u = u < 0 ? 0 : (u > p->umax ? p->umax : u);
  double f = -p->kf * u * ps;                 /* the lagged pickoff is in phase with -velocity */
  d[0] = v;
  d[1] = f - p->wd * p->wd * x - p->wd / p->Qd * v + 2 * p->rate * w - p->kq * y;
  d[2] = w;
  d[3] = -p->ws * p->ws * y - p->ws / p->Qs * w - 2 * p->rate * v - p->kq * x;
  d[4] = p->wl * (p->gps * vx - ps);          /* first-order lag far below the carrier: ~90 degrees */
  d[5] = p->wa * (fabs(ps) - a);              /* full-wave rectifier and low-pass */
  d[6] = e;                                   /* PI integrator */
  d[7] = o2;                                  /* demodulator and 2nd-order Butterworth */
  d[8] = p->wo * p->wo * (vs * vx - o1) - 1.4142135623730951 * p->wo * o2;
}
int ref_rollout(const refp* p, double* s, long n_out, long m, double* out) {
  double k1[9], k2[9], k3[9], k4[9], t[9];
  const double h = p->h;
  for (long o = 0; o < n_out; ++o) {
    for (long j = 0; j < m; ++j) {
      rhs(s, k1, p);
      for (int i = 0; i < 9; ++i) t[i] = s[i] + 0.5 * h * k1[i];
      rhs(t, k2, p);
      for (int i = 0; i < 9; ++i) t[i] = s[i] + 0.5 * h * k2[i];
      rhs(t, k3, p);
      for (int i = 0; i < 9; ++i) t[i] = s[i] + h * k3[i];
      rhs(t, k4, p);
      for (int i = 0; i < 9; ++i) s[i] += h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
    }
    memcpy(out + 9 * o, s, sizeof(double) * 9);
  }
  return 0;
}
"""


class Reference:
    """The plain-C RK4 reference loop, compiled with ``gcc -O2`` into a temporary folder."""

    F_DRIVE_HZ, F_SENSE_HZ, Q, AMP_M, PICKOFF_V_PER_M = 30740.0, 30886.0, 5000.0, 0.7e-6, 1e6

    def __init__(self, steps_per_cycle: int):
        cc = shutil.which("gcc") or shutil.which("cc")
        if cc is None:
            raise SystemExit("benchmarks/carrier.py: the C reference needs gcc")
        self._tmp = tempfile.TemporaryDirectory()
        src, lib = Path(self._tmp.name) / "ref.c", Path(self._tmp.name) / "ref.so"
        src.write_text(REFERENCE_C)
        subprocess.run([cc, "-O2", "-fPIC", "-shared", str(src), "-o", str(lib), "-lm"], check=True)
        self.lib = ctypes.CDLL(str(lib))
        wd, ws, Q, A0, kpick = 2 * np.pi * self.F_DRIVE_HZ, 2 * np.pi * self.F_SENSE_HZ, self.Q, self.AMP_M, \
            self.PICKOFF_V_PER_M
        tau = 2 * Q / wd
        kp = 2 * np.pi * 20 / ((2 / np.pi) * kpick * A0 / tau)  # 20 Hz amplitude-loop crossover
        self.h = 1.0 / (steps_per_cycle * self.F_DRIVE_HZ)
        fields = dict(wd=wd, ws=ws, Qd=Q, Qs=Q, rate=1.0, kq=0.01 * wd ** 2, kpick=kpick, wl=wd / 20,
                      gps=20.0 * np.sqrt(1 + 1 / 400), wa=2 * np.pi * 200, vref=(2 / np.pi) * kpick * A0, kp=kp,
                      ki=kp * 2 * np.pi * 20 / 5, umax=5.0, kf=wd ** 2 / (Q * kpick), wo=2 * np.pi * 100, h=self.h)

        class P(ctypes.Structure):
            _fields_ = [(k, ctypes.c_double) for k in fields]
        self.p = P(**fields)
        self.lib.ref_rollout.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.c_long,
                                         ctypes.c_long, ctypes.POINTER(ctypes.c_double)]

    def run(self, sim_s: float, output_rate_Hz: float = 1000.0):
        """Simulate ``sim_s`` from a 10 nm start; (steps, final amplitude estimate / set-point)."""
        m = max(1, int(round(1.0 / (output_rate_Hz * self.h))))
        n_out = max(1, int(np.ceil(sim_s / (m * self.h))))
        s = np.zeros(9)
        s[0] = 10e-9
        out = np.empty((n_out, 9))
        dp = ctypes.POINTER(ctypes.c_double)
        self.lib.ref_rollout(ctypes.byref(self.p), s.ctypes.data_as(dp), n_out, m, out.ctypes.data_as(dp))
        return n_out * m, out[-1, 5] / self.p.vref


def scenario(sim_s: float, spc: int, extra=()):
    return load_scenario(REPO / "scenarios" / "startup.toml",
                         overrides=[f"scenario.duration_s={sim_s}", f"scenario.steps_per_cycle={spc}",
                                    "scenario.output_rate_Hz=1000", "initial.state=\"steady\"", *extra])


def population(n: int, sim_s: float, spc: int):
    """``n`` units of config A with manufacturing tolerances (Q, frequencies, gains) and their own seeds."""
    rng = np.random.default_rng(2024)
    units = []
    for k in range(n):
        q, fd, fs, kp = rng.normal([2.0e4, 30740.0, 30886.0, 68.0], [1.5e3, 2.0, 2.0, 3.0])
        units.append(scenario(sim_s, spc, [f"device.mechanics.q_drive={q:.6g}", f"device.mechanics.f_drive_Hz={fd:.8g}",
                                           f"device.mechanics.f_sense_Hz={fs:.8g}", f"device.circuit.pi.kp={kp:.6g}",
                                           f"scenario.seed={100 + k}"]))
    return units


def timed(fn):
    t0, c0 = time.perf_counter(), time.thread_time()
    out = fn()
    return time.perf_counter() - t0, time.thread_time() - c0, out


def rollout_case(spc: int):
    """The compiled roll-out on its own: config A at 25 C, one block of samples."""
    scn = scenario(0.01, spc)
    dev = scn.device
    ref = dev.reference_diagram
    h = 1.0 / (spc * ref.resonator.f_drive_Hz)
    plan = make_plan(build_diagram(dev, 25.0), h, None, ref.core_state_scale())
    M = int(round(1.0 / (1000.0 * h)))
    return plan, initial_state(plan, from_steady=True), M


def baseline_rhs(dg):
    """The diagram's continuous-time right-hand side (numpy), for solve_ivp (``--solve-ivp``)."""
    ss = steady_state(dg)
    g0 = ss.modulator_gain
    S = dg.core_state_scale()
    c0, cg = dg.core_system(g0), dg.core_system(g0 + 1.0)
    A0 = (1 / S)[:, None] * np.asarray(c0.A) * S[None, :]
    Ag = (1 / S)[:, None] * (np.asarray(cg.A) - np.asarray(c0.A)) * S[None, :]
    C = np.asarray(c0.C) * S[None, :]
    la, lo = dg.amplitude_lpf.linear_model(), dg.output_lpf.linear_model()
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
        ri, rq = n * (cr * vps - sr * vx), n * (cr * vx + sr * vps)
        return np.concatenate([dz, Aa @ sa + Ba * abs(vps), [e], Ao @ si + Bo * km * vs * ri,
                               Ao @ sq + Bo * km * vs * rq])

    y0 = np.zeros(15)
    y0[0] = ss.amplitude_m / S[0]
    y0[8] = dg.vref_V
    y0[10] = ss.agc_effort_V / ki
    return f, y0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    ap.add_argument("--sim-s", type=float, default=1.0, help="simulated seconds per timed run")
    ap.add_argument("--reps", type=int, default=5, help="interleaved repetitions (best of)")
    ap.add_argument("--units", default="", help="comma-separated population sizes for run_carrier_units, e.g. 4,8")
    ap.add_argument("--steps-per-cycle", type=int, default=32)
    ap.add_argument("--solve-ivp", action="store_true", help="also time scipy solve_ivp (LSODA) on 0.002 s")
    a = ap.parse_args()
    spc = a.steps_per_cycle
    sizes = [int(s) for s in a.units.split(",") if s.strip()]
    ref = Reference(spc)
    t0 = time.perf_counter()
    roll = load_rollout(CARRIER_MODEL, log=lambda m: None)
    lanes = load_rollout(CARRIER_MODEL, log=lambda m: None, lanes=True) if sizes else None
    load_s = time.perf_counter() - t0
    scn = scenario(a.sim_s, spc)
    run_carrier(scenario(0.01, spc), progress=False)  # warm: library, imports, the 25 C operating point
    plan, x0, M = rollout_case(spc)
    K = max(1, int(round(a.sim_s / (M * ref.h) / 10)))  # a tenth of a run's samples per roll-out call
    P = plan.params(np.zeros(K))
    pops = {n: population(n, a.sim_s, spc) for n in sizes}
    for units in pops.values():
        run_carrier_units(units, progress=False)  # their operating points, once
    best: dict = {}

    def keep(name, wall, cpu, per):
        w, c = best.get(name, (np.inf, np.inf))
        best[name] = (min(w, wall / per), min(c, cpu / per))

    amp_ok = True
    for _ in range(a.reps):
        wall, cpu, (steps, amp) = timed(lambda: ref.run(a.sim_s))
        keep("reference", wall, cpu, steps)
        amp_ok &= abs(amp - 1.0) < 0.01
        wall, cpu, _ = timed(lambda: roll(x0, P, None, M, seed=1))
        keep("roll-out", wall, cpu, K * M)
        wall, cpu, res = timed(lambda: run_carrier(scn, progress=False))
        n_steps = len(res["time_s"]) * res.info["steps_per_sample"]
        keep("run", wall, cpu, n_steps)
        engine._PLANS.clear()
        wall, cpu, _ = timed(lambda: run_carrier(scn, progress=False))
        keep("first run", wall, cpu, n_steps)
        for n, units in pops.items():
            wall, cpu, rs = timed(lambda: run_carrier_units(units, progress=False))
            keep(f"units {n}", wall, cpu, sum(len(r["time_s"]) * r.info["steps_per_sample"] for r in rs))
    r_wall, r_cpu = best["reference"]
    rows = {k: dict(ns_per_step=w * 1e9, cpu_ns_per_step=c * 1e9, ratio=w / r_wall, cpu_ratio=c / r_cpu)
            for k, (w, c) in best.items()}
    out = dict(baseline="plain-C RK4 reference loop (9 states, gcc -O2)", steps_per_cycle=spc, sim_s=a.sim_s,
               reps=a.reps, reference_settles=bool(amp_ok), compiled=roll.compiled, library_load_s=load_s,
               cache=str(cache_dir()), cases=rows)
    if a.solve_ivp:
        from scipy.integrate import solve_ivp
        f, y0 = baseline_rhs(build_diagram(scn.device, 25.0))
        wall, cpu, sol = timed(lambda: solve_ivp(f, (0, 0.002), y0, method="LSODA", rtol=1e-8, atol=1e-10,
                                                 max_step=1e-5))
        out["solve_ivp_s_per_sim_s"] = wall / 0.002
        out["solve_ivp_ratio_to_run"] = (wall / 0.002) / (best["run"][0] / ref.h)
    if a.json:
        print(json.dumps(out))
        return 0
    print(f"{'case':<22}{'ns/step':>9}{'CPU ns':>9}{'x C ref':>9}{'CPU x':>8}   "
          f"(best of {a.reps}, {a.sim_s:g} s simulated, {spc} steps/cycle, noise on)")
    for k, r in rows.items():
        label = "C reference (RK4, -O2)" if k == "reference" else (f"{k} (per unit)" if k.startswith("units") else k)
        print(f"{label:<22}{r['ns_per_step']:9.1f}{r['cpu_ns_per_step']:9.1f}{r['ratio']:9.2f}{r['cpu_ratio']:8.2f}")
    if not amp_ok:
        print("warning: the C reference's amplitude loop did not settle; its figure is not comparable")
    if a.solve_ivp:
        print(f"solve_ivp LSODA on the same diagram: {out['solve_ivp_s_per_sim_s']:.0f} s per simulated s, "
              f"{out['solve_ivp_ratio_to_run']:.0f}x the run")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
