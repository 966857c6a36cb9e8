"""Make the README's pictures (docs/img/*.png) by running the README's tour.

Runs the tour's commands in a scratch folder (a few minutes on two cores), then writes a small copy
of one plot per step into docs/img/. The compensation step has no plot of its own, so this script
draws one from the compensated records.

Usage: python docs/make_images.py [--work DIR]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

IMG = Path(__file__).resolve().parent / "img"
#: Width of the pictures in the README, pixels.
WIDTH_PX = 720

#: The tour, as in the README: (step, fmvmg arguments).
TOUR = [
    ("run", ["run", "startup", "-o", "startup"]),
    ("allan", ["run", "static_25C", "-o", "static", "--no-plots"]),
    ("allan", ["allan", "static/record.csv", "-o", "static_allan"]),
    ("tune", ["tune", "-o", "tune"]),
    ("compensate", ["run", "oven_000", "--set", "scenario.output_rate_Hz=10", "-o", "oven_000", "--no-plots"]),
    ("compensate", ["run", "oven_004", "--set", "scenario.output_rate_Hz=10", "-o", "oven_004", "--no-plots"]),
    ("compensate", ["compensate", "oven_004/record.csv", "--method", "poly-baseline", "--train",
                    "oven_000/record.csv", "-o", "comp_poly"]),
    ("compensate", ["compensate", "oven_004/record.csv", "--method", "physics", "--train",
                    "oven_000/record.csv", "-o", "comp_physics"]),
    ("diagnose", ["run", "oven_000", "--set", "scenario.output_rate_Hz=1", "--set", "effects.thermal_lag.tau_s=600",
                  "-o", "oven_lag", "--no-plots"]),
    ("diagnose", ["diagnose", "oven_lag/record.csv", "--scenario", "nominal_a", "-o", "diagnosis"]),
]

#: Picture of each step: (plot in the scratch folder, picture in docs/img).
PICTURES = [("startup/startup.png", "run_startup.png"), ("static_allan/allan.png", "allan.png"),
            ("tune/step.png", "tune_step.png"), ("compensation.png", "compensate.png"),
            ("diagnosis/residual_temperature.png", "diagnose.png")]


def _compensation_plot(work: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from fmvmg_sim import read_record
    poly = read_record(work / "comp_poly" / "compensated.csv")
    phys = read_record(work / "comp_physics" / "compensated.csv")
    t_h = poly.time_s / 3600.0
    k = max(1, len(t_h) // 4000)

    def mean(y):
        m = len(y) // k * k
        return np.asarray(y[:m]).reshape(-1, k).mean(axis=1)

    fig, ax = plt.subplots(3, 1, figsize=(8, 6.5), sharex=True, gridspec_kw={"height_ratios": [1, 1.2, 2]})
    ax[0].plot(mean(t_h), mean(poly["temperature_C"]), color="C3")
    ax[0].set_ylabel("temperature (C)")
    ax[1].plot(mean(t_h), mean(poly["rate_raw_dps"]) * 3600.0, lw=0.8, color="0.3", label="raw")
    ax[1].set_ylabel("raw (deg/h)")
    ax[1].legend(fontsize=8, loc="lower right")
    for y, label, c in ((poly["rate_dps"], "poly-baseline (T, T^2, dT/dt)", "C1"),
                        (phys["rate_dps"], "physics (auxiliary channels)", "C2")):
        ax[2].plot(mean(t_h), mean(y) * 3600.0, lw=0.8, color=c, label=label)
    ax[2].set_ylabel("compensated (deg/h)")
    ax[2].set_xlabel("time (h)")
    ax[2].legend(fontsize=8, loc="lower left")
    ax[0].set_title("oven_004 compensated, each method fitted on oven_000 (held out)")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(work / "compensation.png", dpi=110)
    plt.close(fig)


def _small_copy(src: Path, dst: Path) -> None:
    from PIL import Image
    with Image.open(src) as im:
        h = round(im.height * WIDTH_PX / im.width)
        im.convert("RGB").resize((WIDTH_PX, h), Image.LANCZOS).quantize(colors=128).save(dst, optimize=True)


def main() -> int:
    """Run the tour and write the pictures.

    Returns
    -------
    int
        Exit code.
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default=None, help="scratch folder (default: a temporary one, removed)")
    ap.add_argument("--pictures-only", action="store_true",
                    help="skip the tour: make the pictures from an earlier run's --work folder")
    a = ap.parse_args()
    if a.pictures_only and a.work is None:
        ap.error("--pictures-only needs --work")
    from fmvmg_sim.cli.main import main as fmvmg
    work = Path(a.work or tempfile.mkdtemp(prefix="fmvmg-tour-"))
    work.mkdir(parents=True, exist_ok=True)
    here = Path.cwd()
    try:
        import os
        os.chdir(work)
        for step, argv in ([] if a.pictures_only else TOUR):
            sys.stderr.write(f"[{step}] fmvmg {' '.join(argv)}\n")
            rc = fmvmg(argv + (["--no-progress"] if argv[0] in ("run", "compensate", "diagnose") else []))
            if rc != 0:
                sys.stderr.write(f"fmvmg {argv[0]} failed with exit code {rc}\n")
                return rc
        _compensation_plot(work)
        IMG.mkdir(exist_ok=True)
        for src, dst in PICTURES:
            _small_copy(work / src, IMG / dst)
            sys.stderr.write(f"wrote {IMG / dst} ({(IMG / dst).stat().st_size // 1024} KiB)\n")
    finally:
        os.chdir(here)
        if a.work is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
