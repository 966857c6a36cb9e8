"""PNG plots of the tuning: Bode of the loop gain, step responses, start-up, sweep heat map (atomic writes)."""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np

from ..plots import plt, save_figure


def plot_bode(loops: dict, path: str | Path) -> None:
    """Bode plot of the loop gains L(jw), one line per (gain set, temperature).

    Parameters
    ----------
    loops : dict
        Label -> :class:`fmvmg_sim.tuning.linear_loop.LinearLoop`.
    path : str or Path
    """
    w = np.logspace(0, 4.5, 600)
    fig, ax = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for k, (label, loop) in enumerate(loops.items()):
        H = np.asarray(control.frequency_response(loop.loop_gain, w).complex).ravel()
        ls = ("-", "--", ":")[k % 3]
        color = f"C{k // 3}"
        ax[0].semilogx(w / (2 * np.pi), 20 * np.log10(np.abs(H)), ls, color=color, label=label)
        ax[1].semilogx(w / (2 * np.pi), np.rad2deg(np.unwrap(np.angle(H))), ls, color=color)
    ax[0].axhline(0, color="k", lw=0.6)
    ax[1].axhline(-180, color="k", lw=0.6)
    ax[1].axhline(-120, color="r", lw=0.6, ls=":", label="-120 deg (60 deg phase margin)")
    ax[0].set_ylabel("|L| (dB)")
    ax[1].set_ylabel("arg L (deg)")
    ax[1].set_xlabel("frequency (Hz)")
    ax[0].legend(fontsize=7, ncol=2)
    ax[1].legend(fontsize=7, loc="lower left")
    ax[0].set_title("Drive amplitude loop gain (linearised)")
    for a in ax:
        a.grid(alpha=0.3, which="both")
    fig.tight_layout()
    save_figure(fig, path)


def plot_steps(checks: list, path: str | Path, predicted_only: list | None = None) -> None:
    """Normalised 10 % set-point step: linear prediction against the carrier simulation.

    Parameters
    ----------
    checks : list of StepCheck
        Simulated checks (prediction and simulation).
    path : str or Path
    predicted_only : list of LoopMetrics, optional
        Predictions without a simulation (``--no-sim``).
    """
    fig, ax = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for k, c in enumerate(checks):
        lab = f"Kp={c.kp:.4g} Ki={c.ki_per_s:.4g}, {c.temperature_C:g} C"
        ax[0].plot(c.predicted.t_s * 1e3, c.predicted.r_unit, color=f"C{k}", lw=1, label=f"{lab} linear")
        ax[0].plot(c.t_s * 1e3, c.r_simulated_unit, ".", ms=2, color=f"C{k}", label=f"{lab} carrier sim")
        ax[1].plot(c.predicted.t_s * 1e3, c.predicted.u_unit * 0.1 * c.predicted.params.vref_V + c.predicted.u0_V,
                   color=f"C{k}", lw=1)
    for k, m in enumerate(predicted_only or []):
        lab = f"Kp={m.kp:.4g} Ki={m.ki_per_s:.4g}, {m.temperature_C:g} C"
        ax[0].plot(m.t_s * 1e3, m.r_unit, color=f"C{k}", lw=1, label=f"{lab} linear")
        ax[1].plot(m.t_s * 1e3, m.u_unit * 0.1 * m.params.vref_V + m.u0_V, color=f"C{k}", lw=1)
    ax[0].axhspan(0.98, 1.02, color="0.85", label="2 % band")
    ax[0].set_ylabel("r, normalised step")
    ax[1].set_ylabel("PI output u (V), linear")
    ax[1].set_xlabel("time after the step (ms)")
    tmax = max([4 * c.predicted.settling_time_s for c in checks]
               + [4 * m.settling_time_s for m in (predicted_only or [])] + [0.02])
    ax[1].set_xlim(0, min(tmax, 1.0) * 1e3)
    ax[0].legend(fontsize=6)
    ax[0].set_title("10 % Vref step from the steady state")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def plot_startups(checks: list, path: str | Path) -> None:
    """Start-up from rest: carrier engine against the averaged large-signal model.

    Parameters
    ----------
    checks : list of StartupCheck
    path : str or Path
    """
    fig, ax = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for k, c in enumerate(checks):
        ax[0].plot(c.t_s * 1e3, c.r_simulated_V, color=f"C{k}", lw=1.5, alpha=0.6,
                   label=f"{c.temperature_C:g} C carrier")
        ax[0].plot(c.t_s * 1e3, c.r_predicted_V, "--", color=f"C{k}", lw=1, label=f"{c.temperature_C:g} C averaged")
        ax[1].plot(c.t_s * 1e3, c.u_simulated_V, color=f"C{k}", lw=1.5, alpha=0.6)
        ax[1].plot(c.t_s * 1e3, c.u_predicted_V, "--", color=f"C{k}", lw=1)
    ax[0].set_ylabel("amplitude estimate r (V)")
    ax[1].set_ylabel("PI output u (V)")
    ax[1].set_xlabel("time (ms)")
    ax[0].legend(fontsize=7)
    ax[0].set_title("Start-up with the tuned gains")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def plot_sweep_heatmap(sweep, path: str | Path, marks: dict | None = None) -> None:
    """Heat map of the worst-case (over temperature) settling time over (Kp, Ki).

    Parameters
    ----------
    sweep : SweepResult
    path : str or Path
    marks : dict, optional
        Label -> (Kp, Ki) points to mark (robust, pole-zero rule, current).
    """
    g = sweep.worst_settling_grid() * 1e3
    kp, ki = np.asarray(sweep.kp_values), np.asarray(sweep.ki_values)
    fig, ax = plt.subplots(figsize=(8, 6))
    masked = np.ma.masked_invalid(g)
    if masked.count():
        mesh = ax.pcolormesh(kp, ki, masked, shading="nearest", cmap="viridis_r",
                             norm=_log_norm(masked))
        fig.colorbar(mesh, ax=ax, label="worst-case 2 % settling time (ms)")
    bad = ~np.isfinite(g)
    if bad.any():
        KP, KI = np.meshgrid(kp, ki)
        ax.plot(KP[bad], KI[bad], "x", color="0.5", ms=5, label="violates PM/GM/overshoot/u_max")
    for k, (label, (p, i)) in enumerate((marks or {}).items()):
        ax.plot([p], [i], "o", mfc="none", mec=f"C{k + 1}", ms=10, mew=2, label=label)
    ax.set_xlabel("Kp")
    ax.set_ylabel("Ki (1/s)")
    ax.set_title(f"Gain sweep over {len(sweep.temperatures_C)} temperatures")
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    save_figure(fig, path)


def _log_norm(a):
    from matplotlib.colors import LogNorm
    lo, hi = float(a.min()), float(a.max())
    return LogNorm(vmin=lo, vmax=max(hi, lo * 1.01))
