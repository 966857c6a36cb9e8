"""Plots of a population study: each limited figure's histogram with its limits, and the top drivers' scatter."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..plots import save_figure
from .figures import FIGURES
from .study import PopulationResult

#: Drivers shown in the scatter plot.
TOP_DRIVERS = 3


def plot_histograms(pop: PopulationResult, path: str | Path) -> None:
    """Histogram of each figure of merit (the spec's limited figures first) with the spec's limits.

    Parameters
    ----------
    pop : PopulationResult
    path : str or Path
        PNG file.
    """
    limits = pop.spec.limits if pop.spec else {}
    names = list(limits) + [f for f in FIGURES if f not in limits and np.isfinite(pop.figure(f)).any()]
    ncol = min(3, len(names))
    nrow = -(-len(names) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.0 * nrow), squeeze=False)
    for ax, name in zip(axes.flat, names):
        v = pop.figure(name)
        ok = v[np.isfinite(v)]
        ax.hist(ok, bins=max(5, min(40, int(np.sqrt(ok.size)) * 2)), color="tab:blue", alpha=0.8)
        lim = limits.get(name, {})
        for key, style in (("min", "-"), ("max", "-"), ("max_abs", "--")):
            if key in lim:
                for x in ((-lim[key], lim[key]) if key == "max_abs" else (lim[key],)):
                    ax.axvline(x, color="tab:red", ls=style, lw=1.5)
        if lim and ok.size:
            fail = len(v) - int(pop.spec.pass_table([{name: x} for x in v]).sum())
            unread = len(v) - ok.size
            ax.set_title(f"{name}\n{fail - unread} of {len(v)} outside" + (f", {unread} not read" if unread else ""),
                         fontsize=9)
        else:
            ax.set_title(name, fontsize=9)
        ax.set_ylabel("units")
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    title = f"{pop.scenario}: {len(pop.units)} units"
    if pop.yield_fraction is not None:
        title += f", yield {pop.yield_fraction:.1%} against {pop.spec.name}"
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path)


def plot_drivers(pop: PopulationResult, path: str | Path, drivers: list | None = None) -> None:
    """The top drivers' deviations against the figure each correlates with most, passes and failures marked.

    Parameters
    ----------
    pop : PopulationResult
    path : str or Path
        PNG file.
    drivers : list of dict, optional
        :meth:`PopulationResult.drivers` (computed when not given).
    """
    rows = (drivers if drivers is not None else pop.drivers())[:TOP_DRIVERS]  # scatter against the failing figure
    names = list(pop.knobs)
    passed = pop.passed
    fails = {}
    if pop.spec is not None:
        table = pop.spec.pass_table([u["figures"] for u in pop.units])
        fails = {f: int((~table[:, j]).sum()) for j, f in enumerate(pop.spec.limits)}
    fig, axes = plt.subplots(1, max(1, len(rows)), figsize=(4.5 * max(1, len(rows)), 3.6), squeeze=False)
    for ax, row in zip(axes.flat, rows):
        rho = {f: r for f, r in row["spearman"].items() if np.isfinite(r)}
        failing = {f: r for f, r in rho.items() if f in fails and fails[f] > 0} or rho
        fname = max(failing, key=lambda f: abs(failing[f])) if failing else next(iter(row["spearman"]), None)
        x = pop.draws[:, names.index(row["knob"])]
        if fname is None:
            continue
        y = pop.figure(fname)
        ax.scatter(x[passed], y[passed], s=10, color="tab:blue", label="pass")
        ax.scatter(x[~passed], y[~passed], s=10, color="tab:red", label="fail")
        lim = pop.spec.limits.get(fname, {}) if pop.spec else {}
        for key in ("min", "max", "max_abs"):
            if key in lim:
                for v in ((-lim[key], lim[key]) if key == "max_abs" else (lim[key],)):
                    ax.axhline(v, color="tab:red", lw=1, ls="--")
        ax.set_xlabel(f"{row['knob']} (tolerance {row['tolerance']:g})")
        ax.set_ylabel(fname)
        ax.set_title(f"failure-rate spread {row['score']:.2f}, rho {rho.get(fname, float('nan')):+.2f}", fontsize=9)
        ax.legend(fontsize=8)
    fig.suptitle(f"{pop.scenario}: the tolerances that drive the failures")
    fig.tight_layout()
    save_figure(fig, path)
