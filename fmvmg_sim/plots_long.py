"""Plots of long (oven, static) runs: temperature and rate against time, rate against temperature, Allan deviation."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plots import plt, save_figure
from .result import SimResult


def _decimate(x: np.ndarray, n_max: int = 20000) -> np.ndarray:
    """Block means so a plot has at most ``n_max`` points."""
    k = max(1, len(x) // n_max)
    m = len(x) // k * k
    return x[:m].reshape(-1, k).mean(axis=1) if k > 1 else x


def plot_long_run(res: SimResult, out: str | Path) -> None:
    """Write ``temperature_rate.png``, ``rate_vs_temperature.png`` and ``allan.png`` into ``out``.

    Parameters
    ----------
    res : SimResult
    out : str or Path
        Output folder.
    """
    out = Path(out)
    t = res.time_s
    th = _decimate(t) / 3600.0
    T = _decimate(res["temperature_C"])
    rate = _decimate(res["rate_dps"])
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax[0].plot(th, T, color="C3")
    ax[0].set_ylabel("temperature (C)")
    ax[1].plot(th, rate, lw=0.6)
    ax[1].set_ylabel("rate output (deg/s)")
    ax[1].set_xlabel("time (h)")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, out / "temperature_rate.png")

    dT = np.gradient(T, th * 3600.0) if len(T) > 2 else np.zeros_like(T)
    fig, ax = plt.subplots(figsize=(7, 5))
    for mask, label, color in ((dT > 1e-4, "heating", "C3"), (dT < -1e-4, "cooling", "C0"),
                               (np.abs(dT) <= 1e-4, "hold", "0.5")):
        if mask.any():
            ax.plot(T[mask], rate[mask], ".", ms=2, color=color, label=label)
    ax.set_xlabel("temperature (C)")
    ax.set_ylabel("rate output (deg/s)")
    ax.legend(markerscale=5)
    ax.grid(alpha=0.3)
    ax.set_title("Rate output against temperature")
    fig.tight_layout()
    save_figure(fig, out / "rate_vs_temperature.png")

    from .analysis import allan_deviation
    fs = 1.0 / float(np.median(np.diff(t)))
    if len(t) > 100:
        allan_deviation(res["rate_dps"], fs).plot(out / "allan.png")
