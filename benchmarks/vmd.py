"""Wall time and peak memory of :func:`fmvmg_sim.compensation.vmd.vmd` on a long gyro-like record.

Usage: ``python benchmarks/vmd.py [--n 1000000] [--K 6] [--json]``. Run it alone on the
machine (it is single-threaded but memory-bandwidth bound). Budget: K = 6 on
1e6 samples in <= 60 s and <= 2 GB peak resident memory.
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import numpy as np


def gyro_like(n: int, fs_Hz: float = 100.0, seed: int = 0) -> np.ndarray:
    """White rate noise (100 deg/h/rtHz), a random walk and a slow thermal drift, in deg/s.

    Parameters
    ----------
    n : int
        Number of samples.
    fs_Hz : float, optional
        Sampling rate.
    seed : int, optional
        Random seed.

    Returns
    -------
    ndarray
    """
    rng = np.random.default_rng(seed)
    t_s = np.arange(n) / fs_Hz
    white = rng.standard_normal(n) * (100.0 / 3600.0) * np.sqrt(fs_Hz)
    walk = np.cumsum(rng.standard_normal(n)) * (0.5 / 3600.0) / np.sqrt(fs_Hz)
    drift = (60.0 / 3600.0) * (1.0 - np.exp(-t_s / 900.0))
    return white + walk + drift


def main(argv: list[str] | None = None) -> dict:
    """Run the benchmark and print wall seconds and peak MB.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments.

    Returns
    -------
    dict
        ``n``, ``K``, ``wall_s``, ``cpu_s`` (process CPU time: the wall time on an idle
        machine), ``peak_rss_MB``, ``iterations``, ``converged``, ``residual_fraction``.
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--K", type=int, default=6)
    ap.add_argument("--max-iter", type=int, default=500)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    from fmvmg_sim.compensation.vmd import vmd

    y = gyro_like(args.n)
    t0, c0 = time.perf_counter(), time.process_time()
    res = vmd(y, K=args.K, alpha=2000.0, tau=0.0, tol=1e-7, DC=False, init=1, max_iter=args.max_iter)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    out = {"n": args.n, "K": args.K, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
           "peak_rss_MB": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
           "iterations": res.iterations, "converged": res.converged,
           "residual_fraction": round(res.residual_fraction(), 4)}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"vmd K={args.K} n={args.n}: {out['wall_s']} s wall ({out['cpu_s']} s CPU), "
              f"{out['peak_rss_MB']} MB peak RSS, "
              f"{res.iterations} iterations (converged={res.converged}), residual {out['residual_fraction']:.1%} of SD")
    return out


if __name__ == "__main__":
    main()
