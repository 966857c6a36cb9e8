"""Figures of the diagnosis: residuals with regimes, residual against temperature by direction,
Allan curves (measured, nominal, corrected), gap before and after."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .forward import IRATE


def plot_all(rep: dict, out: Path) -> list[str]:
    """Draw every figure into ``out``.

    Parameters
    ----------
    rep : dict
        Report with its ``_plot`` data.
    out : Path

    Returns
    -------
    list of str
        Files written.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d = rep["_plot"]
    prep, f = d["prep"], d["fitter"]
    sf = prep.sf_nominal_V_per_dps
    tb = prep.block_time_s() / 3600.0
    r_nom = (f.Y[:, IRATE] - d["pred_cal"][:, IRATE]) / sf
    r_fin = (f.Y[:, IRATE] - d["final_tr"][:, IRATE]) / sf
    files = []
    # 1 residual vs time with regimes shaded
    fig, ax = plt.subplots(figsize=(10, 4))
    for name, col in (("heating", "tab:red"), ("cooling", "tab:blue")):
        m = prep.block_regime(name)
        ax.fill_between(tb, 0, 1, where=m, color=col, alpha=0.12, transform=ax.get_xaxis_transform(), label=name)
    ax.plot(tb, r_nom, lw=0.7, label="calibrated nominal")
    if d["final_ho"] is not None:
        ax.plot(tb, r_fin, lw=0.7, label="with accepted effects")
    for fd in prep.folds():
        ax.axvline(fd["test_start_s"] / 3600.0, color="k", ls=":", lw=0.8)
    ax.set_xlabel("time (h)")
    ax.set_ylabel("rate residual (deg/s)")
    ax.set_title(f"verdict: {rep['verdict']} {rep['accepted']}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "residual_time.png", dpi=110)
    plt.close(fig)
    files.append("residual_time.png")
    # 2 residual vs temperature by direction
    T = prep.block_mean(prep.case_C)
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, col in (("heating", "tab:red"), ("cooling", "tab:blue"), ("hold", "0.5")):
        m = prep.block_regime(name)
        ax.plot(T[m], r_nom[m], ".", ms=2, color=col, label=name)
    ax.set_xlabel("sensor temperature (C)")
    ax.set_ylabel("rate residual (deg/s)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "residual_temperature.png", dpi=110)
    plt.close(fig)
    files.append("residual_temperature.png")
    # 3 Allan curves
    fig, ax = plt.subplots(figsize=(6, 4))
    st = d["st_meas"].get("_allan")
    if st is not None:
        ax.loglog(st[0], st[1] * 3600, label="measured - calibrated nominal")
    for k, s in enumerate(d["st_null"]):
        a = s.get("_allan")
        if a is not None:
            ax.loglog(a[0], a[1] * 3600, color="0.6", lw=0.7, label="nominal re-simulated (null)" if k == 0 else None)
    t2, a2 = d["meas_ho_allan"]
    if len(a2):
        ax.loglog(t2, a2 * 3600, label="held-out, corrected model (slow trends removed)")
    ax.set_xlabel("tau (s)")
    ax.set_ylabel("Allan deviation of the residual (deg/h)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "allan.png", dpi=110)
    plt.close(fig)
    files.append("allan.png")
    # 4 gap before and after
    fig, ax = plt.subplots(figsize=(8, 4))
    keys = list(d["before"])
    b = np.array([np.sqrt(d["before"][k]) for k in keys])
    a = np.array([(d["after"] or {}).get(k, np.nan) for k in keys])
    x = np.arange(len(keys))
    ax.bar(x - 0.2, b / np.where(b > 0, b, 1), 0.4, label="before (normalised)")
    ax.bar(x + 0.2, np.nan_to_num(a) / np.where(b > 0, b, 1), 0.4, label="after")
    ax.set_xticks(x, keys, rotation=30, ha="right", fontsize=7)
    ax.set_ylabel("held-out gap / gap before")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "gap_before_after.png", dpi=110)
    plt.close(fig)
    files.append("gap_before_after.png")
    return files
