"""Log-log PNG of an Allan deviation with its confidence band and the IEEE 952 lines.

Uses matplotlib's object API with the Agg canvas (no pyplot, no global backend switch), and
writes the PNG to a temporary file in the destination folder that is then renamed over it.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np

from ..output import file_mode


def plot_allan(result, path: str | os.PathLike, title: str | None = None) -> None:
    """Write the Allan curve of ``result`` as a PNG.

    Parameters
    ----------
    result : AllanResult
        The analysis to draw: curve, CI band, the power-law sum the ARW is read from (over its fit
        range), fitted -1 / -1/2 lines (read at sqrt(3) s and 1 s),
        the Allan minimum (0 line) and the +1/2 line (read at 3 s), each over its fit region
        (solid) and extended (dotted).
    path : path-like
        Destination PNG file.
    title : str, optional
        Title; default ``"Allan deviation of <column>"``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    t, s = result.taus_s, result.adev
    pos = s > 0
    fig = Figure(figsize=(7.0, 5.0), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.fill_between(t[pos], result.adev_lo[pos], result.adev_hi[pos], color="tab:blue", alpha=0.2,
                    label=f"{100 * result.ci:.1f} % CI")
    ax.loglog(t[pos], s[pos], "o-", color="tab:blue", ms=3, lw=1.2, label="OADEV")
    few = pos & (result.n_clusters < result.min_clusters)
    if few.any():
        ax.loglog(t[few], s[few], "o", mfc="white", color="tab:blue", ms=4,
                  label=f"< {result.min_clusters} clusters (not fitted)")
    tt = np.array([t[0], t[-1]]) if len(t) else np.array([1.0, 1.0])
    unit = result.unit
    lines = [
        (result.quantization, math.sqrt(3.0), "tab:purple", f"-1: Q = {_fmt(result.Q)} {unit}*s"),
        (result.white, 1.0, "tab:green", _white_label(result)),
        (result.random_walk, 3.0, "tab:red", _rrw_label(result)),
    ]
    for term, tau_read, color, label in lines:
        if term.value is None:
            continue
        line = term.value * (tt / tau_read) ** term.slope
        ax.loglog(tt, line, ":", color=color, lw=1)
        r = np.array(term.region_s)
        ax.loglog(r, term.value * (r / tau_read) ** term.slope, "-", color=color, lw=2.5, label=label)
    pl = result.power_law
    if pl is not None:  # the power-law sum the ARW is read from, over its fit range
        tf = np.geomspace(pl["tau_first_s"], pl["tau_last_s"], 60)
        s2 = pl["C"] / tf ** 2 + pl["N2"] / tf + pl["B2"] + pl["K2"] * tf / 3.0
        ax.loglog(tf, np.sqrt(np.clip(s2, 0.0, None)), "--", color="black", lw=1,
                  label="power-law fit (ARW's white term)")
    if result.allan_minimum is not None:
        ax.axhline(result.allan_minimum, color="tab:orange", ls="--", lw=1, label=_bi_label(result))
        ax.plot([result.tau_min_s], [result.allan_minimum], "s", color="tab:orange", ms=6)
    ax.set_xlabel("averaging time tau [s]")
    ax.set_ylabel(f"overlapping Allan deviation [{unit}]")
    ax.set_title(title or f"Allan deviation of {result.column or 'the signal'}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fig.savefig(fh, format="png")
        os.chmod(tmp, file_mode())  # the umask's permissions, not mkstemp's 0600
        os.replace(tmp, p)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _fmt(v) -> str:
    return "n/a" if v is None else f"{v:.4g}"


def _white_label(r) -> str:
    if r.is_deg_per_s:
        return f"-1/2: ARW N = {_fmt(r.arw_deg_per_sqrt_h)} deg/sqrt(h)"
    return f"-1/2: N = {_fmt(r.N)} {r.unit}*sqrt(s)"


def _rrw_label(r) -> str:
    if r.is_deg_per_s:
        return f"+1/2: RRW K = {_fmt(r.rrw_deg_per_h_sqrt_h)} deg/h/sqrt(h)"
    return f"+1/2: K = {_fmt(r.K)} {r.unit}/sqrt(s)"


def _bi_label(r) -> str:
    if r.is_deg_per_s:
        return (f"0: Allan minimum {_fmt(r.bias_instability_deg_per_h)} deg/h at {r.tau_min_s:.3g} s "
                f"(IEEE B = {_fmt(r.bias_instability_ieee952_deg_per_h)})")
    return f"0: Allan minimum {_fmt(r.allan_minimum)} {r.unit} at {r.tau_min_s:.3g} s"
