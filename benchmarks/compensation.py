"""Benchmarks and calibrations of paper 000's compensation pipeline (run one at a time).

    python benchmarks/compensation.py [--json]            # emd-rbf-ga-kf on 13 h at 100 Hz: wall time, peak memory
    python benchmarks/compensation.py --emd-choice        # PyEMD vs emd timings (1e4, 1e5; emd also 1e6)
    python benchmarks/compensation.py --calibrate-se      # sample-entropy thresholds from labelled synthetic IMFs
    python benchmarks/compensation.py --holdout           # in-sample vs held-out numbers (mean, SD, n over 5 seeds)

Targets for the default run: <= 5 min and <= 4 GB on the project's 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np


def _peak_rss_MB() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def pipeline(hours: float = 13.0, method: str = "emd-rbf-ga-kf", synthetic: bool = False) -> dict:
    """Fit and compensate one record in-sample; wall time and peak RSS.

    The record is the simulator's paper-004 oven (13.1 h at 100 Hz, envelope engine), or with
    ``synthetic`` a synthetic cycle record of ``hours``.
    """
    from fmvmg_sim.compensation import get_method
    from fmvmg_sim.compensation.synthetic import make_record

    t0 = time.perf_counter()
    if synthetic:
        rec = make_record(hours * 3600.0, 100.0, "cycle", "static", seed=0)
    else:
        from pathlib import Path
        from fmvmg_sim.envelope.engine import run_envelope
        from fmvmg_sim.scenario import load_scenario
        path = Path(__file__).resolve().parents[1] / "scenarios" / "oven_004.toml"
        over = [] if hours is None or hours >= 13.0 else [f"scenario.duration_s={hours * 3600.0}"]
        rec = run_envelope(load_scenario(path, overrides=over), progress=False).to_record()
    t_gen = time.perf_counter() - t0
    comp = get_method(method)(progress=True)
    t1 = time.perf_counter()
    out = comp.fit_transform(rec)["rate_dps"]
    wall = time.perf_counter() - t1
    d = comp.fit_diagnostics_
    return {"method": method, "n_samples": len(rec), "generate_s": round(t_gen, 1), "wall_s": round(wall, 1),
            "peak_rss_MB": round(_peak_rss_MB()),
            "target": "<= 600 s" if method == "vmd-wflp-cssvr" else "<= 300 s, <= 4096 MB",
            "n_imfs": d.get("n_imfs"), "classes": d.get("classes"), "kf": d.get("kf"),
            "truth_rms_before_dph": float(np.sqrt(np.mean(rec["rate_dps"] ** 2)) * 3600),
            "truth_rms_after_dph": float(np.sqrt(np.mean(out**2)) * 3600)}


_EMD_CHILD = """
import sys, time, resource, warnings, numpy as np
warnings.simplefilter("ignore")
which, n = sys.argv[1], int(float(sys.argv[2]))
rng = np.random.default_rng(0); fs = 100.0; t = np.arange(n) / fs
x = (100/3600)*np.sqrt(fs)*rng.standard_normal(n) + np.cumsum(rng.standard_normal(n))*(0.5/3600)/np.sqrt(fs) \\
    + 0.01*np.tanh(t/900)
if which == "pyemd":
    from PyEMD import EMD; f = lambda: EMD(spline_kind="cubic")(x)
else:
    import emd; f = lambda: emd.sift.sift(x).T
ts = []
for _ in range(int(sys.argv[3])):
    t0 = time.perf_counter(); imfs = f(); ts.append(time.perf_counter() - t0)
print(float(np.median(ts)), imfs.shape[0], resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
"""


def emd_choice() -> list[dict]:
    """Median wall time of PyEMD and emd on the same gyro-like signal, each run in a fresh process."""
    rows = []
    for lib, n, reps in [("emd", 1e4, 3), ("pyemd", 1e4, 3), ("emd", 1e5, 3), ("pyemd", 1e5, 3), ("emd", 1e6, 1)]:
        out = subprocess.run([sys.executable, "-c", _EMD_CHILD, lib, str(n), str(reps)], capture_output=True,
                             text=True, check=True).stdout.split()
        rows.append({"library": lib, "n": int(n), "median_s": round(float(out[0]), 3), "n_components": int(out[1]),
                     "peak_rss_MB": round(float(out[2]))})
    return rows


def imf_labels(imfs: np.ndarray, residue: np.ndarray, comp: dict) -> np.ndarray:
    """Label each IMF by the known components it holds (shares of <imf, component> / <imf, y>).

    Mixed where the true rate holds >= 20 %; else noise where white noise holds >= 80 %;
    else drift where thermal + flicker + RRW hold >= 80 %; else mixed.
    """
    from fmvmg_sim.compensation.sampen import DRIFT, MIXED, NOISE

    src = {"signal": comp["true"] + comp["scale"], "noise": comp["white"],
           "drift": comp["thermal"] + comp["flicker"] + comp["rrw"]}
    labels = []
    for c in imfs:
        c = c - c.mean()
        tot = sum(float(c @ (v - v.mean())) for v in src.values())
        share = {k: float(c @ (v - v.mean())) / tot for k, v in src.items()}
        labels.append(MIXED if share["signal"] >= 0.2 else NOISE if share["noise"] >= 0.8
                      else DRIFT if share["drift"] >= 0.8 else MIXED)
    return np.array(labels, int)


def calibrate_se(hours: float = 1.0, seeds=(11, 12)) -> dict:
    """Calibrate the noise/drift sample-entropy thresholds on labelled synthetic records."""
    from fmvmg_sim.compensation import sampen
    from fmvmg_sim.compensation.emd import emd_decompose
    from fmvmg_sim.compensation.synthetic import make_record

    ents, labs, cases = [], [], []
    for profile in ("heating", "cooling", "ramp"):
        for rate in ("static", "mixed"):
            for seed in seeds:
                rec, comp = make_record(hours * 3600, 100.0, profile, rate, seed=seed, return_components=True)
                res = emd_decompose(rec["rate_dps"], 100.0)
                e = sampen.imf_entropies(res.imfs)
                lab = imf_labels(res.imfs, res.residue, comp)
                ents.append(e)
                labs.append(lab)
                cases.append({"profile": profile, "rate": rate, "seed": seed, "se": np.round(e, 3).tolist(),
                              "labels": lab.tolist()})
                print(f"{profile:8s} {rate:6s} seed {seed}: labels {lab.tolist()}", file=sys.stderr)
    nm, dm, acc = sampen.calibrate_thresholds(ents, labs)

    def acc_of(a, b, sel=None):
        pairs = [(e, l) for (e, l, c) in zip(ents, labs, cases) if sel is None or c["rate"] == sel]
        return sum(int((sampen.classify(e, a, b) == l).sum()) for e, l in pairs) / sum(len(l) for _, l in pairs)

    subsets = {}
    for sel in ("static", "mixed"):
        idx = [i for i, c in enumerate(cases) if c["rate"] == sel]
        snm, sdm, sacc = sampen.calibrate_thresholds([ents[i] for i in idx], [labs[i] for i in idx])
        subsets[sel] = {"noise_se_min": snm, "drift_se_max": sdm, "accuracy": sacc,
                        "accuracy_with_overall_thresholds": acc_of(nm, dm, sel)}
    return {"noise_se_min": nm, "drift_se_max": dm, "accuracy": acc,
            "accuracy_at_start_point": acc_of(0.8 * sampen.WHITE_NOISE_SE, 0.1),
            "sensitivity": {f"x{f}": acc_of(nm * f, min(dm * f, nm * f)) for f in (0.5, 0.8, 1.25, 2.0)},
            "per_rate_kind": subsets, "n_imfs_labelled": int(sum(map(len, labs))), "cases": cases}


def holdout(hours: float = 2.0, fs_Hz: float = 10.0, seeds=(21, 22, 23, 24, 25)) -> dict:
    """Train on a static heating run; score in-sample and on held-out runs (other profiles, seeds).

    The three pipeline variants share each record's decomposition (identical by construction).
    Returns mean and SD over seeds of every metric, per method and case.
    """
    from fmvmg_sim.cli.compensate import metrics
    from fmvmg_sim.compensation import get_method
    from fmvmg_sim.compensation.poly import rate_error
    from fmvmg_sim.compensation.synthetic import make_record

    methods = ("poly-baseline", "emd-rbf", "emd-rbf-ga", "emd-rbf-ga-kf")
    cases = {"in_sample": None, "held_out_cooling": ("cooling", "static"), "held_out_ramp": ("ramp", "static"),
             "held_out_cooling_dynamic": ("cooling", "mixed")}
    rows = {m: {c: [] for c in cases} for m in ("raw",) + methods}
    for seed in seeds:
        train = make_record(hours * 3600, fs_Hz, "heating", "static", seed=seed)
        recs = {c: train if p is None else make_record(hours * 3600, fs_Hz, *p, seed=seed + 100)
                for c, p in cases.items()}
        probe = get_method("emd-rbf")()
        dec_train = probe._decompose(train.time_s, rate_error(train), fs_Hz)
        decs = {c: probe._decompose(r.time_s, r["rate_dps"], fs_Hz) for c, r in recs.items()}
        for c, r in recs.items():
            rows["raw"][c].append(metrics(r))
        for m in methods:
            comp = get_method(m)()
            pipe = m != "poly-baseline"
            comp.fit(train, _decomp=(dec_train[0], dict(dec_train[1]))) if pipe else comp.fit(train)
            for c, r in recs.items():
                out = (comp.compensate_rate_dps(r, _decomp=(decs[c][0], dict(decs[c][1]))) if pipe
                       else comp.compensate_rate_dps(r))
                rows[m][c].append(metrics(r, out))
            print(f"seed {seed}: {m} done", file=sys.stderr)
    return {"setup": {"hours": hours, "fs_Hz": fs_Hz, "seeds": list(seeds), "train": "heating, static",
                      "cases": {c: p or "the training record" for c, p in cases.items()}},
            **{m: {c: _mean_sd(v) for c, v in cs.items()} for m, cs in rows.items()}}


def _mean_sd(rows: list[dict]) -> dict:
    out = {}
    for k in rows[0]:
        vals = [r[k] for r in rows if r[k] is not None]
        out[k] = [float(np.mean(vals)), float(np.std(vals)), len(vals)] if vals else None
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--emd-choice", action="store_true")
    g.add_argument("--calibrate-se", action="store_true")
    g.add_argument("--holdout", action="store_true")
    ap.add_argument("--hours", type=float, default=None)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--synthetic", action="store_true", help="a synthetic record instead of the simulated oven_004")
    ap.add_argument("--method", default="emd-rbf-ga-kf", help="the method to time (default emd-rbf-ga-kf)")
    a = ap.parse_args()
    if a.emd_choice:
        res = emd_choice()
    elif a.calibrate_se:
        res = calibrate_se(a.hours or 1.0)
    elif a.holdout:
        res = holdout(a.hours or 2.0)
    else:
        res = pipeline(a.hours or 13.0, method=a.method, synthetic=a.synthetic)
    print(json.dumps(res) if a.json else json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
