"""Where the gap lies against the training window: the record-design note of a diagnosis.

Forward-chained attribution fits every candidate on the training window of the last fold (the record up to
76 % of its length, :meth:`~.data.Prepared.folds`) and tests it on later blocks. A gap whose evidence lies
after that window (an oven ramp, a relaxation or a step only the record's end holds) cannot be attributed by
any forward-chained fit, however strong it is over the whole record: the parameters that would explain it are
not determined where they are fitted. Such records are a common cause of a missed effect in the benchmark, whose
labels say so (:func:`fmvmg_sim.validation.cases.training_snr`); the diagnoser cannot read a label, so this module
finds the same thing from the record alone.

The statistic is the mean square of each channel's normalised residual of the final model (the nominal model
when nothing was accepted; fitted on the training window and extrapolated after it), on the training window
and after it, each compared with the same statistic of the null replicates read against their own calibration
on the same window (:func:`.localize.compare`: Student-t on the log, spread floored by sliding the window along
the replicates). The note fires when a channel's excess after the training window is significant (Holm's
correction over the channels) and its excess on the training window is not significant even uncorrected (a
guard that errs towards silence): what the model leaves lies where no training window reaches. It is advice on the record's design, never an attribution, and
it changes no verdict.
"""

from __future__ import annotations

import numpy as np

from . import localize as loc
from .data import Prepared
from .forward import CHANNELS

#: Family-wise error rate of the note's tests after the training window (Holm over the channels); the guard on
#: the training window is read at this level uncorrected.
ALPHA = loc.ALPHA
WINDOWS = ("train", "after")


def window_masks(prep: Prepared, train_b: np.ndarray) -> dict:
    """The last fold's training window and the blocks after it.

    Parameters
    ----------
    prep : Prepared
    train_b : ndarray of bool
        The last fold's training blocks.

    Returns
    -------
    dict
        ``{"train": mask, "after": mask}`` over blocks; ``after`` is every block later than the last training
        block (the gap before the last test segment included).
    """
    tb = prep.block_time_s()
    end = float(tb[train_b].max()) if train_b.any() else -np.inf
    return {"train": np.asarray(train_b, bool), "after": tb > end}


def window_stats(prep: Prepared, Zb: np.ndarray, masks: dict) -> dict:
    """Each channel's mean square residual in each window, shaped for :func:`.localize.compare`.

    Parameters
    ----------
    prep : Prepared
    Zb : ndarray, shape (n_blocks, C)
        Normalised block residuals.
    masks : dict
        From :func:`window_masks`.

    Returns
    -------
    dict
        ``{"channels": {"<channel>@<window>": mean square}, "allan_bands": {}, "regimes": {}, "_sd_floor": ...}``.
    """
    out = {"channels": {}, "allan_bands": {}, "regimes": {}, "_sd_floor": {}}
    for i, c in enumerate(CHANNELS):
        if c not in prep.channels:
            continue
        for w in WINDOWS:
            m = masks[w] & np.isfinite(Zb[:, i])
            if m.sum() < 5:
                continue
            key = f"{c}@{w}"
            out["channels"][key] = float(np.mean(Zb[m, i] ** 2))
            out["_sd_floor"][key] = loc.window_log_ms_sd(Zb[:, i], int(m.sum()))
    return out


def after_training_note(measured: dict, nulls: list[dict], train_end_s: float, alpha: float = ALPHA) -> dict:
    """Whether the gap the final model leaves lies after the training window only.

    Parameters
    ----------
    measured : dict
        :func:`window_stats` of the record's residual.
    nulls : list of dict
        :func:`window_stats` of each null replicate's residual.
    train_end_s : float
        Time of the last training block (s).
    alpha : float, optional

    Returns
    -------
    dict
        ``fires`` (bool), ``after_s`` (``train_end_s``), ``channels`` (those whose excess lies after the
        window only), ``tests`` (``{"<channel>@<window>": {value, null_mean, z, p, p_holm, significant}}``) and,
        when it fires, ``advice``.
    """
    def part(st: dict, w: str) -> dict:
        keep = {k: v for k, v in st["channels"].items() if k.endswith("@" + w)}
        return {"channels": keep, "allan_bands": {}, "regimes": {},
                "_sd_floor": {k: v for k, v in st.get("_sd_floor", {}).items() if k in keep}}
    res = {}
    for w in WINDOWS:
        res.update(loc.compare(part(measured, w), [part(n, w) for n in nulls], alpha)["channels"])
    for k, v in res.items():
        if k.endswith("@train"):  # the guard: any excess on the training window at the unadjusted level
            v["significant"] = bool(v["p"] < alpha)
    chans = []
    for c in CHANNELS:
        after, train = res.get(f"{c}@after"), res.get(f"{c}@train")
        if after and after["significant"] and not (train and train["significant"]):
            chans.append(c)
    tests = {k: {f: v[f] for f in ("value", "null_mean", "z", "p", "p_holm", "significant")} for k, v in res.items()}
    out = {"fires": bool(chans), "after_s": float(train_end_s), "channels": chans, "tests": tests}
    if chans:
        out["advice"] = (f"what the model leaves lies after the last training window (from {train_end_s / 3600:.2f} h) "
                         f"in {', '.join(chans)}, not on it: forward-chained attribution fits every effect on that "
                         "window, so this part of the gap cannot be attributed from this record. Extend the record "
                         "past it, or repeat the same excitation (ramp, hold, temperature) earlier in the profile")
    return out
