"""PNG plots of a run (matplotlib, Agg backend); every file is written atomically."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .result import SimResult  # noqa: E402


def save_figure(fig, path: str | Path) -> None:
    """Save ``fig`` to ``path`` whole or not at all, then close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or Path
    """
    p = Path(path)
    tmp = p.with_name(f".{p.stem}.{os.getpid()}.tmp.png")
    try:
        fig.savefig(tmp, dpi=110)
        os.replace(tmp, p)
    finally:
        plt.close(fig)
        if tmp.exists():
            tmp.unlink()


def plot_startup(res: SimResult, vref_V: np.ndarray, path: str | Path) -> None:
    """Start-up envelope: amplitude estimate against its set-point, AGC effort, mechanical amplitude.

    Parameters
    ----------
    res : SimResult
    vref_V : ndarray
    path : str or Path
    """
    t = res.time_s
    fig, ax = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    ax[0].plot(t, res["drive_amplitude_V"], label="drive amplitude estimate (rectifier + LPF)")
    ax[0].plot(t, vref_V, "k--", lw=1, label="set-point Vref")
    ax[0].set_ylabel("V")
    ax[0].legend(loc="lower right")
    ax[1].plot(t, res["agc_effort_V"], color="C1")
    ax[1].set_ylabel("AGC effort u (V)")
    if "drive_displacement_amplitude_m" in res.internal:
        ax[2].plot(t, res.internal["drive_displacement_amplitude_m"] * 1e6, color="C2")
    ax[2].set_ylabel("drive amplitude (um)")
    ax[2].set_xlabel("time (s)")
    ax[0].set_title("Drive loop start-up")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def plot_channels(res: SimResult, path: str | Path) -> None:
    """Every record channel against time.

    Parameters
    ----------
    res : SimResult
    path : str or Path
    """
    t = res.time_s
    names = [("rate_dps", "rate (deg/s)"), ("quadrature_V", "quadrature (V)"), ("drive_amplitude_V", "drive amp. (V)"),
             ("agc_effort_V", "AGC effort (V)"), ("drive_frequency_Hz", "drive freq. (Hz)"),
             ("temperature_C", "temperature (C)")]
    fig, ax = plt.subplots(len(names), 1, figsize=(8, 10), sharex=True)
    for a, (k, label) in zip(ax, names):
        a.plot(t, res[k], lw=0.8)
        if k == "rate_dps":
            a.plot(t, res["rate_true_dps"], "k--", lw=0.8, label="applied rate")
            a.legend(loc="upper right")
        a.set_ylabel(label)
        a.grid(alpha=0.3)
    ax[-1].set_xlabel("time (s)")
    fig.tight_layout()
    save_figure(fig, path)
