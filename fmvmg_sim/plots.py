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


def _thin(t: np.ndarray, *ys, n_max: int = 20000):
    """Block means so a plot has at most ``n_max`` points per line."""
    k = max(1, len(t) // n_max)
    if k == 1:
        return (t, *ys)
    m = len(t) // k * k
    return tuple(np.asarray(a)[:m].reshape(-1, k).mean(axis=1) for a in (t, *ys))


def drive_loop_title(name: str, state: str, duration_s: float) -> str:
    """Title of the drive-loop plot for what it shows: a start-up, or the loop held over a run.

    Parameters
    ----------
    name : str
        Scenario name.
    state : str
        The scenario's ``initial.state``: ``"rest"`` (a start-up) or ``"steady"``.
    duration_s : float
        Simulated time.

    Returns
    -------
    str
    """
    if state == "rest":
        return f"{name}: drive loop start-up"
    span = f"{duration_s / 3600:.3g} h" if duration_s >= 7200 else f"{duration_s:.3g} s"
    return f"{name}: drive amplitude loop over {span} (started at its steady state)"


def _time_axis(t: np.ndarray) -> tuple[np.ndarray, str]:
    span = float(t[-1] - t[0]) if len(t) else 0.0
    if span >= 7200:
        return t / 3600.0, "time (h)"
    if span >= 600:
        return t / 60.0, "time (min)"
    return t, "time (s)"


def plot_startup(res: SimResult, vref_V: np.ndarray, path: str | Path, title: str = "Drive loop start-up") -> None:
    """Drive amplitude loop: amplitude estimate against its set-point, AGC effort, mechanical amplitude.

    Parameters
    ----------
    res : SimResult
    vref_V : ndarray
    path : str or Path
    title : str, optional
        The figure title (see :func:`drive_loop_title`).
    """
    mech = res.internal.get("drive_displacement_amplitude_m", np.full(len(res.time_s), np.nan))
    t, amp, vref, u, mech = _thin(res.time_s, res["drive_amplitude_V"], vref_V, res["agc_effort_V"], mech)
    t, xlabel = _time_axis(t)
    fig, ax = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    ax[0].plot(t, amp, label="drive amplitude estimate (rectifier + LPF)")
    ax[0].plot(t, vref, "k--", lw=1, label="set-point Vref")
    ax[0].set_ylabel("V")
    ax[0].legend(loc="lower right")
    ax[1].plot(t, u, color="C1")
    ax[1].set_ylabel("AGC effort u (V)")
    ax[2].plot(t, mech * 1e6, color="C2")
    ax[2].set_ylabel("drive amplitude (um)")
    ax[2].set_xlabel(xlabel)
    ax[0].set_title(title)
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
    names = [("rate_dps", "rate (deg/s)"), ("quadrature_V", "quadrature (V)"), ("drive_amplitude_V", "drive amp. (V)"),
             ("agc_effort_V", "AGC effort (V)"), ("drive_frequency_Hz", "drive freq. (Hz)"),
             ("temperature_C", "temperature (C)")]
    fig, ax = plt.subplots(len(names), 1, figsize=(8, 10), sharex=True)
    for a, (k, label) in zip(ax, names):
        t, y = _thin(res.time_s, res[k])
        a.plot(t, y, lw=0.8)
        if k == "rate_dps":
            t, y = _thin(res.time_s, res["rate_true_dps"])
            a.plot(t, y, "k--", lw=0.8, label="applied rate")
            a.legend(loc="upper right")
        a.set_ylabel(label)
        a.grid(alpha=0.3)
    ax[-1].set_xlabel("time (s)")
    fig.tight_layout()
    save_figure(fig, path)
