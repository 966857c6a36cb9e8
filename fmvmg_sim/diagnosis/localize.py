"""Step 2: localise the gap against a null re-simulated from the calibrated nominal model.

The calibrated nominal device is simulated with its noise (:func:`fmvmg_sim.envelope.engine.run_envelope`)
on the record's own temperature and rate, a few times with fresh seeds; each null record goes
through the same residual statistics as the measured one. A statistic is significant when it
lies above its null distribution (Student-t on the log statistic, ``M - 1`` degrees of freedom),
after Holm's correction across all statistics (channels x Allan bands x regimes x direction).
A few replicates estimate a spread poorly, so it is floored: an Allan band at the sampling spread of
an Allan deviation (1/sqrt(2 EDF)), a window's mean square at its spread over all windows of the same
length slid along the replicates (on their independent windows' degrees of freedom).
"""

from __future__ import annotations

import sys

import numpy as np
from scipy import stats
from tqdm import tqdm

from ..analysis.allan import allan_deviation
from ..noise import quantize
from ..profiles import PiecewiseProfile
from ..uncertainty import apply_channels
from .data import Prepared
from .forward import CHANNELS, IQUAD, IRATE

#: Allan bands of the rate residual (tau ranges in s).
ALLAN_BANDS = {"white": (0.0, 2.0), "flicker": (10.0, 300.0), "random_walk": (300.0, 2000.0),
               "drift": (2000.0, np.inf)}
REGIMES = ("hold", "heating", "cooling", "post_ramp_hold", "settled_hold")
ALPHA = 0.05
#: Groups whose significant statistics locate a gap in time or band; the closure check re-reads these. A
#: significant channel-level excess alone still makes a record with no accepted effect "unexplained".
LOCATED = ("allan_bands", "regimes")
#: A located statistic that a model closes by less than this share of its excess over the null (and that
#: stays significant) is an open remainder (:func:`closure`).
CLOSURE_MIN = 0.5
#: A statistic this many null standard deviations *below* its null (p ~ 1e-23 under a null that describes it) is
#: not comparable with the null: the replicates carry something the record does not, and a gap there cannot be
#: located (the drive frequency of a record with fast ramps can fall there: the replicates run on the temperature
#: thinned to a point per 5 s, which cuts every ramp corner).
NOT_COMPARABLE_Z = -10.0


def null_records(scn, devices: list, prep: Prepared, seed: int, progress: bool = False,
                 raw: list | None = None, knobs: list | None = None, delay_s: float = 0.0,
                 quadrature_polarity: float = 1.0) -> list[dict]:
    """Simulate the calibrated nominal model with noise on the record's inputs, once per device.

    Parameters
    ----------
    scn : Scenario
        The nominal scenario (noise switches, engine settings).
    devices : list of Device
        One device per replicate (the calibrated one, or draws from the calibration's spread).
    prep : Prepared
    seed : int
    progress : bool, optional
    raw : list, optional
        When given, each replicate's quantised channels before the record's lattice is applied are appended
        to it.
    knobs : list of dict, optional
        Each replicate's knob values: its channels go through its channel knobs
        (:func:`fmvmg_sim.uncertainty.apply_channels`), as the record's went through the calibrated ones.
    delay_s : float, optional
        How much later than the channels the record's temperature is read: the replicates run on the
        temperature the record's channels saw.
    quadrature_polarity : float, optional
        The sign the record's quadrature output carries against the device's.

    Returns
    -------
    list of dict
        Channel arrays at the record's sample times.
    """
    from ..envelope.engine import run_envelope
    dt = prep.sample_interval_s
    # profiles thinned to one point per ~5 s, keeping both sides of every rate step
    k = max(1, int(round(5.0 / dt)))
    keep = np.zeros(len(prep.t_s), bool)
    keep[::k] = True
    keep[-1] = True
    steps = np.flatnonzero(np.diff(prep.rate_true_dps) != 0)
    keep[steps] = True
    keep[np.minimum(steps + 1, len(keep) - 1)] = True
    tp = np.concatenate([[0.0], prep.t_s[keep]])
    T_seen = np.interp(prep.t_s + delay_s, prep.t_s, prep.case_at_t_C) if delay_s else prep.case_at_t_C
    Tp = np.concatenate([[T_seen[0]], T_seen[keep]])
    rp = np.concatenate([[prep.rate_true_dps[0]], prep.rate_true_dps[keep]])
    idx = np.clip(np.round(prep.t_s / dt).astype(int) - 1, 0, None)
    # the record's own resolution (a coarser converter than the scenario's) applies to the null too
    lattice, offsets = prep.lattice(), prep.lattice_offsets()
    out = []
    bar = tqdm(devices, disable=not progress, file=sys.stderr, desc="null re-simulation", unit="run")
    for k, device in enumerate(bar):
        s = scn.replace(scenario={"duration_s": float(prep.t_s[-1]), "output_rate_Hz": 1.0 / dt,
                                  "seed": int(seed + k), "fidelity": "envelope"},
                        initial={"state": "steady"}, device=device, effects={},
                        temperature=PiecewiseProfile(tp, Tp, []), rate=PiecewiseProfile(tp, rp, []))
        res = run_envelope(s, progress=False, log=lambda m: None)
        i = np.clip(idx, 0, len(res.time_s) - 1)
        x = {c: np.asarray(res[c])[i] for c in CHANNELS}
        x["quadrature_V"] = quadrature_polarity * x["quadrature_V"]
        if knobs is not None:  # the channels the replicate's data acquisition writes (gains read the record's T)
            rec_T = {**x, "temperature_C": prep.case_at_t_C, "time_s": prep.t_s}
            x = {c: v for c, v in apply_channels(knobs[k], rec_T, device.reference_temperature_C).items()
                 if c in CHANNELS}
        if raw is not None:
            raw.append({c: x[c] for j, c in enumerate(CHANNELS) if lattice[j] > 0})
        out.append({c: quantize(x[c] - offsets[j], lattice[j]) + offsets[j] for j, c in enumerate(CHANNELS)})
    return out


def noise_mask(prep: Prepared) -> np.ndarray:
    """Samples the noise statistics are read from: away from rate-table motion (unless that is most of it).

    Parameters
    ----------
    prep : Prepared

    Returns
    -------
    ndarray of bool
    """
    quiet = prep.static_rate_samples()
    return quiet if quiet.mean() >= 0.5 else np.ones_like(quiet)


def residual_stats(prep: Prepared, Zb: np.ndarray, rate_res_dps: np.ndarray, mask_b: np.ndarray | None = None,
                   mask_s: np.ndarray | None = None) -> dict:
    """The localisation statistics of one residual (measured or null).

    Parameters
    ----------
    prep : Prepared
    Zb : ndarray, shape (n_blocks, C)
        Normalised block residuals.
    rate_res_dps : ndarray
        Full-rate rate residual (deg/s), NaN where missing.
    mask_b, mask_s : ndarray of bool, optional
        Restrict to these blocks / samples.

    Returns
    -------
    dict
        ``{group: {name: value}}`` with groups ``channels``, ``allan_bands``, ``regimes``.
    """
    mb = np.ones(prep.n_blocks, bool) if mask_b is None else mask_b
    out = {"channels": {}, "allan_bands": {}, "regimes": {}, "_sd_floor": {}}
    for i, c in enumerate(CHANNELS):
        if c in prep.channels:
            out["channels"][c] = float(np.nanmean(Zb[mb, i] ** 2))
            out["_sd_floor"][c] = window_log_ms_sd(Zb[:, i], int(np.sum(mb & np.isfinite(Zb[:, i]))))
    for r in REGIMES:
        m = mb & prep.block_regime(r)
        if m.sum() >= 5:
            out["regimes"][r] = float(np.nanmean(Zb[m, IRATE] ** 2))
            out["_sd_floor"][r] = window_log_ms_sd(Zb[:, IRATE], int(np.sum(m & np.isfinite(Zb[:, IRATE]))))
    # heating minus cooling at matched temperature (rate and quadrature)
    heat, cool = mb & prep.block_regime("heating"), mb & prep.block_regime("cooling")
    if heat.sum() >= 5 and cool.sum() >= 5:
        T = prep.block_mean(prep.case_C)
        bins = np.arange(np.floor(np.nanmin(T)), np.nanmax(T) + 5, 5.0)
        for i, c in ((IRATE, "rate_V"), (IQUAD, "quadrature_V")):
            if c not in prep.channels:
                continue
            d = []
            for a, b in zip(bins[:-1], bins[1:]):
                h = heat & (T >= a) & (T < b)
                k = cool & (T >= a) & (T < b)
                if h.sum() >= 2 and k.sum() >= 2:
                    d.append(np.nanmean(Zb[h, i]) - np.nanmean(Zb[k, i]))
            if d:
                name = f"heating_minus_cooling_{c}"
                out["regimes"][name] = float(np.mean(np.square(d)))
                # sampling spread of the log of a mean of len(d) squared differences (chi-square with
                # len(d) degrees of freedom when the bins are independent), a floor on the null's spread
                out["_sd_floor"][name] = (float(np.sqrt(2.0 / len(d))), len(d))
    fs = 1.0 / prep.sample_interval_s
    taus, adev, span = residual_allan(prep, rate_res_dps, mask_s)
    if len(adev):
        for b, (lo, hi) in ALLAN_BANDS.items():
            m = (taus >= max(lo, 1.5 / fs)) & (taus <= min(hi, span / 10)) & np.isfinite(adev) & (adev > 0)
            if m.any():
                out["allan_bands"][b] = float(np.mean(np.log(adev[m])))
                # sampling spread of log ADEV (about 1/sqrt(2 EDF), EDF ~ span/tau): a floor on the null's
                # spread, which a few replicates estimate poorly where there are few averages
                edf = np.maximum(span / taus[m] - 1.0, 1.0)
                out["_sd_floor"][b] = (float(np.sqrt(np.mean(1.0 / (2.0 * edf)))), 0.0)
        out["_allan"] = (taus, adev)
    return out


def residual_allan(prep: Prepared, rate_res_dps: np.ndarray, mask_s: np.ndarray | None = None,
                   templates: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """Allan deviation of the rate residual on the quiet samples (of ``mask_s``).

    Parameters
    ----------
    prep : Prepared
    rate_res_dps : ndarray
        Full-rate rate residual (deg/s), NaN where missing.
    mask_s : ndarray of bool, optional
    templates : ndarray, shape (n_samples, k), optional
        Columns whose least-squares fit is removed first (:func:`slow_templates`: a stochastic band test
        then ignores what is left of a deterministic temperature signature).

    Returns
    -------
    taus_s, adev_dps : ndarray
        Empty with fewer than 100 samples.
    span_s : float
        Length of the data behind them.
    """
    quiet = noise_mask(prep)
    ms = quiet if mask_s is None else (mask_s & quiet)
    x = rate_res_dps[ms]
    if templates is not None:
        x = x - project(templates[ms], x)
    x = np.nan_to_num(x - np.nanmean(x))
    fs = 1.0 / prep.sample_interval_s
    if len(x) <= 100:
        return np.array([]), np.array([]), 0.0
    ad = allan_deviation(x, fs)
    return np.asarray(ad.taus_s), np.asarray(ad.adev), len(x) / fs


def slow_templates(prep: Prepared) -> np.ndarray:
    """Deterministic slow signatures a temperature profile leaves in a residual, per sample.

    An offset, the case temperature and its square (a temperature law the model lacks) and the
    temperature rate (a gradient term), each scaled to unit range.

    Parameters
    ----------
    prep : Prepared

    Returns
    -------
    ndarray, shape (n_samples, 4)
    """
    T = np.asarray(prep.case_C, dtype=float)
    u = (T - T.mean()) / max(float(np.ptp(T)), 1e-9)
    r = prep.dTdt_K_per_min / max(float(np.max(np.abs(prep.dTdt_K_per_min))), 1e-9)
    return np.column_stack([np.ones_like(u), u, u * u, r])


def project(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Least-squares fit of ``x`` on the columns of ``A`` (NaN samples skipped, NaN where ``x`` is).

    Parameters
    ----------
    A : ndarray, shape (n, k)
    x : ndarray, shape (n,)

    Returns
    -------
    ndarray, shape (n,)
    """
    ok = np.isfinite(x)
    if ok.sum() <= A.shape[1]:
        return np.zeros_like(x)
    coef = np.linalg.lstsq(A[ok], x[ok], rcond=None)[0]
    return np.where(ok, A @ coef, np.nan)


def window_log_ms_sd(z: np.ndarray, n: int) -> tuple[float, float]:
    """Spread of ``log(mean(z**2))`` over windows of ``n`` consecutive samples of a (null) series.

    A few null replicates estimate the spread of a short window's mean square poorly (a regime of a
    hundred blocks of flicker-correlated rate residual varies by a factor of two from run to run);
    sliding the window over each replicate samples it directly, whatever the correlation.

    Parameters
    ----------
    z : ndarray
        The whole series (NaN allowed).
    n : int
        Finite samples in the window.

    Returns
    -------
    sd : float
        0 when the series holds fewer than two independent windows.
    windows : float
        Independent windows the spread rests on (series length / n).
    """
    x = np.asarray(z, dtype=float)
    ok = np.isfinite(x)
    m = int(ok.sum())
    if n < 5 or m < 2 * n:
        return 0.0, 0.0
    x2 = x[ok] ** 2
    c = np.concatenate([[0.0], np.cumsum(x2)])
    ms = (c[n:] - c[:-n]) / n
    sd = float(np.std(np.log(np.maximum(ms, 1e-300))))
    return sd, m / n


def compare(measured: dict, nulls: list[dict], alpha: float = ALPHA) -> dict:
    """p-values of the measured statistics against the null replicates, with Holm's correction.

    Parameters
    ----------
    measured : dict
    nulls : list of dict
    alpha : float, optional

    Returns
    -------
    dict
        ``{group: {name: {value, null_mean, z, p, p_holm, significant, comparable}}}``; ``comparable`` is false
        where ``z`` lies below :data:`NOT_COMPARABLE_Z` (the null does not describe that statistic; it is never
        significant there either, the test being one-sided).
    """
    rows = []
    for g in ("channels", "allan_bands", "regimes"):
        for name, v in measured[g].items():
            ref = np.array([n[g].get(name, np.nan) for n in nulls])
            ref = ref[np.isfinite(ref)]
            if len(ref) < 2:
                continue
            logs = g != "allan_bands"  # Allan stats are already logs
            mv = np.log(max(v, 1e-300)) if logs else v
            rv = np.log(np.maximum(ref, 1e-300)) if logs else ref
            mu, sd = float(np.mean(rv)), float(np.std(rv, ddof=1))
            # sampling-spread floor: Allan bands from the record's span (the same for every replicate);
            # a window's mean square from sliding it over the null replicates (the measured residual
            # carries the gap's own structure), resting on their independent windows
            df = len(rv) - 1
            if g == "allan_bands":
                floor = measured.get("_sd_floor", {}).get(name, (0.0, 0.0))[0]
            else:
                fl = np.array([n.get("_sd_floor", {}).get(name, (np.nan, 0.0)) for n in nulls], dtype=float)
                floor = float(np.sqrt(np.nanmean(fl[:, 0] ** 2))) if np.isfinite(fl[:, 0]).any() else 0.0
                if floor > sd:
                    df = max(df, int(np.nansum(fl[:, 1])) - 1)
            sd = max(sd, 0.05, floor)
            z = (mv - mu) / (sd * np.sqrt(1 + 1 / len(rv)))
            p = float(stats.t.sf(z, df=df))
            rows.append((g, name, v, mu, sd, z, p))
    # Holm
    order = np.argsort([r[6] for r in rows])
    m = len(rows)
    holm = np.ones(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * rows[i][6]))
        holm[i] = running
    out = {"channels": {}, "allan_bands": {}, "regimes": {}}
    for i, (g, name, v, mu, sd, z, p) in enumerate(rows):
        out[g][name] = {"value": float(v), "null_mean": float(np.exp(mu) if g != "allan_bands" else np.exp(mu)),
                        "z": float(z), "p": p, "p_holm": float(holm[i]), "significant": bool(holm[i] < alpha),
                        "comparable": bool(z >= NOT_COMPARABLE_Z)}
    return out


def significant(loc: dict) -> list[tuple[str, str, float]]:
    """Significant statistics, most significant first.

    Parameters
    ----------
    loc : dict
        From :func:`compare`.

    Returns
    -------
    list of (group, name, p_holm)
    """
    s = [(g, n, d["p_holm"]) for g in ("channels", "allan_bands", "regimes") for n, d in loc[g].items()
         if d["significant"]]
    return sorted(s, key=lambda r: r[2])


def _excess(group: str, value: float, null_log_mean: float) -> float:
    """A statistic's excess over the null in mean-square units (an Allan band holds a mean log deviation)."""
    if group == "allan_bands":
        return max(0.0, float(np.exp(2.0 * value) - np.exp(2.0 * null_log_mean)))
    return max(0.0, float(value - np.exp(null_log_mean)))


def closure(before: dict, measured_after: dict, nulls: list[dict], alpha: float = ALPHA,
            closure_min: float = CLOSURE_MIN) -> dict:
    """Whether a model closes the located gap: each located statistic before and after it, against the null.

    The located statistics (:data:`LOCATED`) that are significant against the null with the calibrated
    nominal model (``before``, from :func:`compare`) are read again with the model's residual
    (``measured_after``, from :func:`residual_stats` on the same record and blocks) against the same null
    replicates, Holm-corrected over the whole after set. Each one's shrink is ``1 - E_after / E_before``,
    ``E`` its excess over the null in mean-square units (a regime's mean square of normalised block
    residuals, an Allan band's squared deviation). A statistic that is still significant after and shrinks
    by less than ``closure_min`` is *open*: the model leaves that part of the gap where it was.

    Parameters
    ----------
    before : dict
        :func:`compare` of the nominal model's statistics.
    measured_after : dict
        :func:`residual_stats` of the model's residual.
    nulls : list of dict
        The null replicates' statistics (the same as for ``before``).
    alpha : float, optional
    closure_min : float, optional

    Returns
    -------
    dict
        ``checked``: one row per located statistic significant before (``group``, ``name``, ``z_before``,
        ``z_after``, ``p_holm_after``, ``shrink``, ``open``); ``open``: the open ones.
    """
    after = compare(measured_after, nulls, alpha)
    rows = []
    for g in LOCATED:
        for name, b in before[g].items():
            a = after[g].get(name)
            if not b["significant"] or a is None:
                continue
            mu = float(np.log(max(b["null_mean"], 1e-300)))
            e0 = _excess(g, b["value"], mu)
            e1 = _excess(g, a["value"], mu)
            shrink = 1.0 - e1 / e0 if e0 > 0 else 1.0
            rows.append({"group": g, "name": name, "z_before": b["z"], "z_after": a["z"],
                         "p_holm_after": a["p_holm"], "shrink": float(shrink),
                         "open": bool(a["significant"] and shrink < closure_min)})
    return {"checked": rows, "open": [r for r in rows if r["open"]]}
