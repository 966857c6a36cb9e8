"""Honest end-to-end evaluation of drift compensators on simulated runs.

For every evaluation seed the simulator makes two oven runs with *different* seeds *and*
temperature profiles -- one shaped like paper 000's oven test (cold soak, then hot soak,
1-2 degC/min ramps) and one like paper 004's (hot soak, then stepped cooling) -- with a
thermal lag between case (the ``temperature_C`` sensor) and die switched on. Each method is
fitted on one run and applied to the other, in both directions ("000->004" and "004->000").
A rate-table run (sines of 10 deg/s at 1, 10 and 50 Hz at three temperatures) measures what
each method does to the signal, with the method fitted on an oven run at the rate table's
sample rate. Simulated runs are cached within a call.

Figures (held-out run unless marked)
------------------------------------
Paper's way (what papers 000 and 004 report):

* ``N_paper``: the Allan deviation read at tau = 1 s whatever the local slope, in
  deg/h/sqrt(Hz) (paper 000's unit) and deg/sqrt(h) (paper 004's);
* ``B_paper``: the global minimum of the Allan curve over every computed tau, in deg/h.

Honest (what filtering cannot fake):

* ``N_valid``: IEEE 952 ARW, fitted only where the local slope is -1/2 +- 0.1
  (:func:`fmvmg_sim.analysis.allan.allan_deviation`); None ("not valid") when the curve has
  no such region, e.g. after heavy low-pass filtering;
* ``B_valid``: the Allan minimum over usable taus (>= 8 clusters) with tau >= 10 x the
  method's longest filter time constant (:func:`filter_time_constant`);
* truth error on the held-out run: RMS and max of (compensated - true) at full rate, and of
  its 100 s means (``drift_*``: the part a low-pass filter cannot remove);
* residual bias per degC: slope of the 10 s means of the residual against temperature;
* gain and phase of compensated/true at 1, 10 and 50 Hz on the rate table (mean over its
  three temperature blocks).

Every figure is given as mean and sample standard deviation over seeds (and both
directions for the held-out figures).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..analysis.allan import allan_deviation, oadev_numpy
from ..compensation.base import get_method
from ..compensation.poly import rate_error
from ..errors import InputError
from ..jsonout import strict
from ..paths import scenarios_dir
from ..record import Record
from ..runner import run_scenario
from ..scenario import load_scenario

#: Name of the uncompensated output in method lists.
RAW = "raw"
#: Methods of the full comparison, in table order.
ALL_METHODS = (RAW, "line", "poly-baseline", "emd-rbf", "emd-rbf-ga", "emd-rbf-ga-kf", "vmd-wflp-cssvr", "physics")
#: Frequencies of the bandwidth check, Hz.
BANDWIDTH_FREQS_HZ = (1.0, 10.0, 50.0)
#: Honest bias instability is read at tau >= this factor x the filter time constant.
TAU_FACTOR = 10.0

SCENARIO_DIR = scenarios_dir()


def _segments(*segs) -> str:
    """TOML inline array of temperature segments: numbers are hold seconds, (T, rate) tuples ramps."""
    parts = []
    for s in segs:
        if isinstance(s, tuple):
            parts.append(f"{{ramp_to_C={float(s[0])},rate_C_per_min={float(s[1])}}}")
        else:
            parts.append(f"{{hold_s={float(s)}}}")
    return "[" + ",".join(parts) + "]"


@dataclass(frozen=True)
class Profile:
    """A simulated oven or rate-table run: base scenario, duration, temperature segments, rate.

    Parameters
    ----------
    scenario : str
        Scenario file in ``scenarios/``.
    duration_s : float
    segments : str or None
        TOML inline array replacing ``temperature.segments`` (None: keep the file's).
    fs_Hz : float
        Output rate.
    description : str
    """

    scenario: str
    duration_s: float
    segments: str | None
    fs_Hz: float
    description: str

    def overrides(self, effects: dict) -> list[str]:
        """``--set`` strings for :func:`fmvmg_sim.scenario.load_scenario`."""
        out = [f"scenario.duration_s={self.duration_s}", f"scenario.output_rate_Hz={self.fs_Hz}"]
        if self.segments is not None:
            out.append(f"temperature.segments={self.segments}")
        for name, params in effects.items():
            inner = ",".join(f"{k}={float(v)}" for k, v in params.items())
            out.append(f"effects.{name}={{{inner}}}")
        return out


def _oven_profiles(quick: bool) -> dict[str, Profile]:
    """The paper-000-like and paper-004-like oven profiles, the bandwidth-training run and the rate table."""
    if quick:
        a = _segments(120, (-5, 5), 240, (45, 5), 240, (25, 5), 120)
        b = _segments(120, (50, 5), 240, (20, 5), 240, (0, 5), 240)
        return {
            "oven_000": Profile("oven_000.toml", 1800.0, a, 20.0, "quick: 25 -> -5 -> 45 -> 25 C at 5 C/min, 4 min holds"),
            "oven_004": Profile("oven_004.toml", 1800.0, b, 20.0, "quick: 25 -> 50 -> 20 -> 0 C at 5 C/min, 4 min holds"),
            "bw_train": Profile("oven_000.toml", 600.0, _segments(60, (45, 5), 120, (25, 5)), 200.0,
                                "quick: 25 -> 45 -> 25 C at 5 C/min"),
            "rate_table": Profile("rate_table.toml", 300.0, None, 200.0, "quick: first 300 s (the 25 C block) of rate_table"),
        }
    a = _segments(300, (-30, 2), 900, (60, 2), 900, (25, 2), 300)
    b = _segments(300, (60, 2), 900, (40, 2), 600, (20, 2), 600, (0, 2), 600, (-20, 2), 600, (-40, 2), 600)
    return {
        "oven_000": Profile("oven_000.toml", 7800.0, a, 100.0,
                            "paper 000 shape: 25 -> -30 -> 60 -> 25 C at 2 C/min, 15 min holds (2.2 h, 100 Hz)"),
        "oven_004": Profile("oven_004.toml", 8250.0, b, 100.0,
                            "paper 004 shape: 25 -> 60 C, then down in 20 C steps to -40 C at 2 C/min, "
                            "10-15 min holds (2.3 h, 100 Hz)"),
        "bw_train": Profile("oven_000.toml", 2040.0, _segments(120, (50, 2), 300, (25, 2), 120), 200.0,
                            "bandwidth training: 25 -> 50 -> 25 C at 2 C/min (34 min, 200 Hz)"),
        "rate_table": Profile("rate_table.toml", 2070.0, None, 200.0, "rate_table.toml at 200 Hz output"),
    }


def merge(evs: list["Evaluation"]) -> "Evaluation":
    """One evaluation from several made with the same seeds and profiles but other methods.

    Parameters
    ----------
    evs : list of Evaluation

    Returns
    -------
    Evaluation
        Methods, runs, bandwidth entries and curves concatenated; summary recomputed.
    """
    cfg = dict(evs[0].config)
    cfg["methods"] = [m for e in evs for m in e.config["methods"]]
    cfg["method_params"] = {k: v for e in evs for k, v in e.config.get("method_params", {}).items()}
    cfg["wall_s"] = sum(e.config.get("wall_s", 0.0) for e in evs)
    cfg["in_sample"] = any(e.config.get("in_sample") for e in evs)
    ev = Evaluation(cfg, [r for e in evs for r in e.runs], [b for e in evs for b in e.bandwidth],
                    curves={k: v for e in evs for k, v in e.curves.items()})
    ev.summary = summarise(ev)
    return ev


def default_effects(quick: bool) -> dict:
    """Unmodelled effects switched on in every evaluation run (a case-to-die thermal lag)."""
    return {"thermal_lag": {"tau_s": 120.0 if quick else 600.0, "offset_K": 0.5}}


class RunCache:
    """Simulated records by (profile, seed), made on first use.

    Parameters
    ----------
    profiles : dict
        Profiles by name.
    effects : dict
        ``[effects]`` table applied to every run.
    """

    def __init__(self, profiles: dict[str, Profile], effects: dict):
        self.profiles, self.effects = profiles, effects
        self._runs: dict[tuple, Record] = {}
        self.sim_wall_s = 0.0
        self.n_simulated = 0

    def get(self, name: str, seed: int) -> Record:
        """The record of profile ``name`` simulated with ``seed`` (cached)."""
        key = (name, seed)
        if key not in self._runs:
            p = self.profiles[name]
            t0 = time.perf_counter()
            scen = load_scenario(SCENARIO_DIR / p.scenario, overrides=p.overrides(self.effects), seed=seed)
            res, _ = run_scenario(scen)
            self._runs[key] = res.to_record()
            self.sim_wall_s += time.perf_counter() - t0
            self.n_simulated += 1
        return self._runs[key]

    def clear(self) -> None:
        """Drop every cached record."""
        self._runs.clear()


# --------------------------------------------------------------------------------------------
# Allan figures
# --------------------------------------------------------------------------------------------
def allan_figures(y: np.ndarray, fs_Hz: float, tau_filter_s: float = 0.0) -> dict:
    """Paper-way and honest Allan figures of a rate series in deg/s.

    Parameters
    ----------
    y : ndarray
        Evenly sampled rate, deg/s.
    fs_Hz : float
        Sample rate.
    tau_filter_s : float
        The method's longest filter time constant (B is read at tau >= 10x this).

    Returns
    -------
    dict
        ``N_paper_dph_rtHz`` and ``N_paper_deg_rt_h`` (Allan deviation at tau = 1 s),
        ``B_paper_dph`` (global minimum), ``slope_at_1s``, ``N_valid_deg_rt_h`` (None when no
        -1/2 +- 0.1 region), ``N_valid_reason``, ``B_valid_dph`` (minimum over usable
        tau >= 10 tau_filter), ``B_valid_tau_min_s``, and the curve (``taus_s``, ``adev_dph``).
    """
    y = np.asarray(y, dtype=float)
    a = allan_deviation(y, fs_Hz)
    m1 = int(round(fs_Hz))
    adev1 = float(oadev_numpy(y, fs_Hz, np.array([m1]))[0]) if m1 >= 1 and len(y) > 3 * m1 else math.nan
    slope1 = float(np.interp(0.0, np.log(a.taus_s), a.slopes)) if np.isfinite(a.slopes).any() else math.nan
    usable = (a.n_clusters >= a.min_clusters) & (a.adev > 0)
    lim = max(TAU_FACTOR * tau_filter_s, 0.0)
    sel = usable & (a.taus_s >= lim)
    if sel.any():
        i = np.flatnonzero(sel)[np.argmin(a.adev[sel])]
        b_valid, b_tau = float(a.adev[i] * 3600.0), float(a.taus_s[i])
    else:
        b_valid, b_tau = None, None
    return {"N_paper_dph_rtHz": adev1 * 3600.0, "N_paper_deg_rt_h": adev1 * 60.0,
            "B_paper_dph": float(np.min(a.adev[a.adev > 0]) * 3600.0) if (a.adev > 0).any() else None,
            "B_paper_tau_s": float(a.taus_s[a.adev > 0][np.argmin(a.adev[a.adev > 0])]) if (a.adev > 0).any() else None,
            "slope_at_1s": slope1,
            "N_valid_deg_rt_h": a.arw_deg_per_sqrt_h, "N_valid_reason": a.white.reason,
            "B_valid_dph": b_valid, "B_valid_tau_min_s": b_tau, "B_valid_from_tau_s": lim,
            "taus_s": a.taus_s.tolist(), "adev_dph": (a.adev * 3600.0).tolist()}


def filter_time_constant(method: str, comp) -> tuple[float, str]:
    """The longest time constant of the filtering a fitted-and-applied method does, in s.

    Parameters
    ----------
    method : str
        Method name.
    comp : Compensator or None
        The compensator after ``transform`` (None for ``raw``).

    Returns
    -------
    (float, str)
        The time constant and where it came from. Every method publishes
        ``filter_time_constant_s`` in its diagnostics and is taken at its word (the EMD methods
        derive it from what they drop and filter: the Kalman filter's 1 / (2 pi f_c), the
        longest dropped noise IMF's mean period / (2 pi), the RBF's embedding window); 0 for raw
        and for the methods that subtract a correction.
    """
    if comp is None:
        return 0.0, "raw output"
    for attr in ("transform_diagnostics_", "diagnostics_", "fit_diagnostics_"):
        d = getattr(comp, attr, None) or {}
        if isinstance(d, dict) and d.get("filter_time_constant_s") is not None:
            return float(d["filter_time_constant_s"]), f"{attr}['filter_time_constant_s']"
    return 0.0, "assumed 0: the method subtracts a correction and publishes no filter"


# --------------------------------------------------------------------------------------------
# Truth figures
# --------------------------------------------------------------------------------------------
def _block_means(x: np.ndarray, m: int) -> np.ndarray:
    n = len(x) // m * m
    return x[:n].reshape(-1, m).mean(axis=1) if n else np.array([])


def truth_figures(record: Record, out: np.ndarray) -> dict:
    """Truth error of a compensated output on a record with ``rate_true_dps``.

    Parameters
    ----------
    record : Record
    out : ndarray
        Compensated rate, deg/s.

    Returns
    -------
    dict
        ``rms_dph``, ``max_dph`` (full rate), ``drift_rms_dph``, ``drift_max_dph`` (100 s means)
        and ``bias_per_C_dph`` (slope of 10 s means of the error against temperature).
    """
    fs = 1.0 / record.sample_interval_s()
    err = np.asarray(out, dtype=float) - record["rate_true_dps"]
    m100, m10 = max(1, int(round(100 * fs))), max(1, int(round(10 * fs)))
    e100 = _block_means(err, m100)
    e10, T10 = _block_means(err, m10), _block_means(record["temperature_C"], m10)
    slope = float(np.polyfit(T10, e10, 1)[0] * 3600.0) if len(e10) > 2 and np.ptp(T10) > 0 else None
    return {"rms_dph": float(np.sqrt(np.mean(err ** 2)) * 3600.0), "max_dph": float(np.max(np.abs(err)) * 3600.0),
            "drift_rms_dph": float(np.sqrt(np.mean(e100 ** 2)) * 3600.0) if len(e100) else None,
            "drift_max_dph": float(np.max(np.abs(e100)) * 3600.0) if len(e100) else None,
            "bias_per_C_dph": slope}


def sine_windows(record: Record, freq_Hz: float, min_blocks: int = 3) -> list[tuple[int, int]]:
    """Index ranges of the record where the true rate is a sine of ``freq_Hz``.

    The rate table's sines are found from the truth itself: the record is cut into blocks of
    whole periods (about 1 s); a block belongs to a sine when the component at ``freq_Hz``
    holds over 99 % of the block's (mean-removed) power. Consecutive blocks are merged and the
    first and last block of each run (the transitions) are left out.

    Parameters
    ----------
    record : Record
    freq_Hz : float
    min_blocks : int
        Fewest interior blocks a window must keep.

    Returns
    -------
    list of (start, stop)
    """
    w = np.asarray(record["rate_true_dps"], dtype=float)
    fs = 1.0 / record.sample_interval_s()
    if freq_Hz >= fs / 2:
        return []
    per = fs / freq_Hz
    L = max(1, int(round(max(1.0, round(freq_Hz)) * per)))  # about 1 s, an integer number of periods
    nb = len(w) // L
    if nb < 1:
        return []
    blk = w[: nb * L].reshape(nb, L)
    blk = blk - blk.mean(axis=1, keepdims=True)
    k = np.arange(L)
    ref = np.exp(-2j * np.pi * freq_Hz * k / fs)
    proj = np.abs(blk @ ref) ** 2 * 2.0 / L
    tot = np.sum(blk ** 2, axis=1)
    is_sine = (tot > 0) & (proj > 0.99 * tot)
    out = []
    for a, b in _true_runs(is_sine):
        a, b = a + 1, b - 1
        if b - a >= min_blocks:
            out.append((a * L, b * L))
    return out


def _true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


def gain_phase(record: Record, out: np.ndarray, freqs=BANDWIDTH_FREQS_HZ) -> dict:
    """Gain and phase of ``out`` relative to the true rate at each frequency.

    Parameters
    ----------
    record : Record
        Rate-table record with ``rate_true_dps``.
    out : ndarray
        Compensated rate.
    freqs : sequence of float

    Returns
    -------
    dict
        ``{"1": {"gain": .., "phase_deg": .., "windows": n}, ...}`` (mean over the windows);
        None values where the record holds no sine of that frequency.
    """
    fs = 1.0 / record.sample_interval_s()
    t = record.time_s
    res = {}
    for f in freqs:
        wins = sine_windows(record, f)
        g, ph = [], []
        for a, b in wins:
            ref = np.exp(-2j * np.pi * f * t[a:b])
            yt = np.sum(record["rate_true_dps"][a:b] * ref)
            yo = np.sum((np.asarray(out[a:b]) - np.mean(out[a:b])) * ref)
            if abs(yt) > 0:
                h = yo / yt
                g.append(abs(h))
                ph.append(math.degrees(math.atan2(h.imag, h.real)))
        res[f"{f:g}"] = {"gain": float(np.mean(g)) if g else None,
                         "phase_deg": float(np.mean(ph)) if ph else None, "windows": len(g),
                         "nyquist_ok": f < fs / 2}
    return res


# --------------------------------------------------------------------------------------------
# The evaluation
# --------------------------------------------------------------------------------------------
def _make(method: str, seed: int, params: dict | None):
    cls = get_method(method)
    names = cls().get_params()
    kw = dict(params or {})
    if "progress" in names:
        kw.setdefault("progress", False)
    if "seed" in names:
        kw.setdefault("seed", seed)
    return cls(**kw)


class DecompositionCache:
    """EMD decompositions shared by the three ``emd-rbf*`` methods within one call.

    ``emd-rbf``, ``emd-rbf-ga`` and ``emd-rbf-ga-kf`` start from the same deterministic
    decomposition (EMD + sample-entropy groups) of the same record; their ``fit`` and
    ``transform`` accept it through ``_decomp``. Computing it once per record and signal saves
    two thirds of the EMD time. Results are identical to calling the methods plainly; when
    a method's signature does not take ``_decomp`` the plain calls are used.
    """

    def __init__(self):
        self._d: dict = {}

    def get(self, comp, record: Record, which: str):
        """(groups, diagnostics copy) of ``record``'s training error (``which="error"``) or rate."""
        key = (id(record), which, getattr(comp, "noise_se_min", None), getattr(comp, "drift_se_max", None))
        if key not in self._d:
            y = rate_error(record) if which == "error" else np.asarray(record["rate_dps"], float)
            comp._check(record)
            self._d[key] = comp._decompose(record.time_s, y, 1.0 / record.sample_interval_s())
        groups, diag = self._d[key]
        return groups, dict(diag)

    def clear(self) -> None:
        """Forget every decomposition."""
        self._d.clear()


def _apply(method: str, train: Record, test: Record, seed: int, params: dict | None,
           decomp: DecompositionCache | None = None):
    """(output on test, fitted compensator, wall s); raw passes ``rate_dps`` through."""
    if method == RAW:
        return np.asarray(test["rate_dps"], float).copy(), None, 0.0
    comp = _make(method, seed, params)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        shared = decomp is not None and method.startswith("emd-rbf") and hasattr(comp, "_decompose")
        if shared:
            try:
                comp.fit(train, _decomp=decomp.get(comp, train, "error"))
                out = np.asarray(comp.compensate_rate_dps(test, _decomp=decomp.get(comp, test, "rate")), dtype=float)
                return out, comp, time.perf_counter() - t0
            except TypeError:
                comp = _make(method, seed, params)
        comp.fit(train)
        out = np.asarray(comp.compensate_rate_dps(test), dtype=float)
    return out, comp, time.perf_counter() - t0


@dataclass
class Evaluation:
    """Everything :func:`evaluate` measured.

    Parameters
    ----------
    config : dict
    runs : list of dict
        One entry per (method, seed, direction) with the figures or an ``error``.
    bandwidth : list of dict
        One entry per (method, seed).
    summary : dict
        Mean/sd per method and figure.
    curves : dict
        Allan curves and traces kept for the plots.
    """

    config: dict
    runs: list = field(default_factory=list)
    bandwidth: list = field(default_factory=list)
    summary: dict = field(default_factory=dict)
    curves: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (curves left out)."""
        return strict({"config": self.config, "summary": self.summary, "runs": self.runs,
                          "bandwidth": self.bandwidth})


DIRECTIONS = (("oven_000", "oven_004"), ("oven_004", "oven_000"))


def evaluate(methods=ALL_METHODS, seeds: int = 5, quick: bool = False, effects: dict | None = None,
             in_sample: bool = False, bandwidth: bool = True, method_params: dict | None = None,
             progress: bool = True, seed_offset: int = 0, share_decomposition: bool = True,
             profiles: dict | None = None) -> Evaluation:
    """Fit every method on one oven run, evaluate it on another, over seeds and both directions.

    Parameters
    ----------
    methods : sequence of str
        Method names (``"raw"`` for the uncompensated output).
    seeds : int
        Evaluation seeds (>= 1; 5 or more for figures worth quoting).
    quick : bool
        Short, low-rate runs (tests, smoke checks).
    effects : dict, optional
        ``[effects]`` for every run (default :func:`default_effects`).
    in_sample : bool
        Also compute the paper-way Allan figures in-sample (fit and apply on the training run,
        as the papers did).
    bandwidth : bool
        Run the rate-table check.
    method_params : dict, optional
        Constructor keyword arguments by method name.
    progress : bool
        tqdm progress bar on stderr.
    seed_offset : int
        First evaluation seed.
    share_decomposition : bool
        Decompose each record once for all ``emd-rbf*`` methods (:class:`DecompositionCache`).
    profiles : dict, optional
        Replace some of the default run profiles (:class:`Profile` by name: ``oven_000``,
        ``oven_004``, ``bw_train``, ``rate_table``).

    Returns
    -------
    Evaluation

    Raises
    ------
    InputError
        Unknown method or fewer than one seed.
    """
    from tqdm import tqdm

    methods = list(dict.fromkeys(methods))
    if not methods:
        raise InputError("no methods given", "--methods")
    for m in methods:
        if m != RAW:
            get_method(m)
    if seeds < 1:
        raise InputError(f"seeds must be >= 1, got {seeds}", "--seeds")
    profiles = {**_oven_profiles(quick), **(profiles or {})}
    effects = default_effects(quick) if effects is None else effects
    cache = RunCache(profiles, effects)
    decomp = DecompositionCache() if share_decomposition else None
    ev = Evaluation(config={
        "methods": methods, "seeds": seeds, "seed_offset": seed_offset, "quick": quick, "effects": effects,
        "profiles": {k: {"scenario": p.scenario, "duration_s": p.duration_s, "fs_Hz": p.fs_Hz,
                         "description": p.description} for k, p in profiles.items()},
        "directions": [f"{a}->{b}" for a, b in DIRECTIONS], "in_sample": in_sample, "bandwidth": bandwidth,
        "run_seeds": "oven_000: 100+s, oven_004: 200+s, bw_train: 300+s, rate_table: 400+s",
        "tau_factor": TAU_FACTOR, "method_params": method_params or {},
        "share_decomposition": share_decomposition})
    run_seed = {"oven_000": 100, "oven_004": 200, "bw_train": 300, "rate_table": 400}
    total = seeds * len(methods)
    bar = tqdm(total=total, desc="compensate-eval", disable=not progress, unit="fit")
    t_start = time.perf_counter()
    for s in range(seed_offset, seed_offset + seeds):
        for m in methods:
            bar.set_postfix_str(f"seed {s} {m}")
            params = (method_params or {}).get(m)
            for tr_name, te_name in DIRECTIONS:
                train, test = cache.get(tr_name, run_seed[tr_name] + s), cache.get(te_name, run_seed[te_name] + s)
                entry = {"method": m, "seed": s, "direction": f"{tr_name}->{te_name}"}
                try:
                    out, comp, wall = _apply(m, train, test, s, params, decomp)
                    tf, tf_src = filter_time_constant(m, comp)
                    fs = 1.0 / test.sample_interval_s()
                    allan = allan_figures(out, fs, tf)
                    entry.update({"wall_s": wall, "filter_time_constant_s": tf, "filter_time_constant_source": tf_src,
                                  **{k: v for k, v in allan.items() if k not in ("taus_s", "adev_dph")},
                                  **truth_figures(test, out)})
                    if comp is not None:
                        entry["diagnostics"] = run_diagnostics(comp)
                    if in_sample:
                        out_in = (np.asarray(train["rate_dps"], float) if comp is None
                                           else np.asarray(comp.compensate_rate_dps(train), float))
                        a_in = allan_figures(out_in, 1.0 / train.sample_interval_s(), tf)
                        entry["in_sample"] = {k: a_in[k] for k in ("N_paper_dph_rtHz", "N_paper_deg_rt_h",
                                                                   "B_paper_dph")}
                    if s == seed_offset:
                        key = (m, entry["direction"])
                        ev.curves[key] = {"taus_s": allan["taus_s"], "adev_dph": allan["adev_dph"],
                                          "tau_filter_s": tf,
                                          "t10": _block_means(test.time_s, int(round(10 * fs))),
                                          "err10_dph": _block_means(out - test["rate_true_dps"],
                                                                    int(round(10 * fs))) * 3600.0,
                                          "T10": _block_means(test["temperature_C"], int(round(10 * fs)))}
                except InputError as exc:
                    entry["error"] = f"InputError: {exc}"
                except Exception as exc:  # a method still being finished must not stop the others
                    entry["error"] = f"{type(exc).__name__}: {exc}"
                ev.runs.append(entry)
            if bandwidth:
                bw = {"method": m, "seed": s}
                try:
                    rt = cache.get("rate_table", run_seed["rate_table"] + s)
                    btrain = cache.get("bw_train", run_seed["bw_train"] + s)
                    out, comp, wall = _apply(m, btrain, rt, s, params, decomp)
                    bw.update({"wall_s": wall, "response": gain_phase(rt, out)})
                    if s == seed_offset:
                        ev.curves[(m, "rate_table")] = _rate_window(rt, out)
                except Exception as exc:
                    bw["error"] = f"{type(exc).__name__}: {exc}"
                ev.bandwidth.append(bw)
            bar.update(1)
        cache.clear()
        if decomp is not None:
            decomp.clear()
    bar.close()
    ev.config.update({"wall_s": time.perf_counter() - t_start, "simulated_runs": cache.n_simulated,
                      "simulation_wall_s": cache.sim_wall_s})
    ev.summary = summarise(ev)
    return ev


def run_diagnostics(comp) -> dict:
    """The few diagnostics of a fitted-and-applied compensator kept per run: what it chose and did.

    Parameters
    ----------
    comp : Compensator

    Returns
    -------
    dict
    """
    out = {}
    fit = getattr(comp, "fit_diagnostics_", None) or getattr(comp, "diagnostics_", None) or {}
    tr = getattr(comp, "transform_diagnostics_", None) or {}
    for d in (fit, tr):
        out.update({k: d[k] for k in ("classes", "n_modes", "drift_model_subtracted", "fallback_temperature_only",
                                      "terms", "decimated_to_Hz", "kf_applied", "n_imfs") if k in d})
    sel = comp.selection_report()
    if sel:
        out["chosen"] = sel["chosen"]
        out["continuation"] = (sel.get("chosen_settings") or {}).get("continuation")
    ex = tr.get("extrapolation")
    if ex:
        out["extrapolated"] = bool(ex.get("any"))
    return out


def _rate_window(rt: Record, out: np.ndarray) -> dict:
    """Short windows of the rate table at the first 1 Hz and 10 Hz sines, for plotting."""
    fs = 1.0 / rt.sample_interval_s()
    win = {}
    for f, span in ((1.0, 4.0), (10.0, 0.5)):
        w = sine_windows(rt, f)
        a = w[0][0] if w else 0
        b = min(len(rt), a + int(round(span * fs)))
        win[f"{f:g}"] = {"t": rt.time_s[a:b], "true": rt["rate_true_dps"][a:b], "out": np.asarray(out[a:b]),
                         "raw": rt["rate_dps"][a:b]}
    return win


#: Figures summarised per method: key -> (source, label).
HELD_OUT_KEYS = ("N_paper_dph_rtHz", "N_paper_deg_rt_h", "B_paper_dph", "slope_at_1s", "N_valid_deg_rt_h",
                 "B_valid_dph", "filter_time_constant_s", "rms_dph", "max_dph", "drift_rms_dph", "drift_max_dph",
                 "bias_per_C_dph", "wall_s")


def _stat(vals) -> dict:
    v = np.array([x for x in vals if x is not None and np.isfinite(x)], dtype=float)
    return {"mean": float(v.mean()) if len(v) else None, "sd": float(v.std(ddof=1)) if len(v) > 1 else None,
            "n": int(len(v)), "n_total": len(vals)}


def summarise(ev: Evaluation) -> dict:
    """Mean, sample SD and counts of every figure per method.

    Parameters
    ----------
    ev : Evaluation

    Returns
    -------
    dict
        ``{method: {figure: {"mean", "sd", "n", "n_total"}, ..., "errors": [...]}}``.
    """
    out = {}
    for m in ev.config["methods"]:
        runs = [r for r in ev.runs if r["method"] == m]
        ok = [r for r in runs if "error" not in r]
        s = {k: _stat([r.get(k) for r in ok]) for k in HELD_OUT_KEYS}
        s["bias_per_C_abs_dph"] = _stat([abs(r["bias_per_C_dph"]) if r.get("bias_per_C_dph") is not None else None
                                         for r in ok])
        if any("in_sample" in r for r in ok):
            for k in ("N_paper_dph_rtHz", "N_paper_deg_rt_h", "B_paper_dph"):
                s[f"in_sample_{k}"] = _stat([r["in_sample"][k] for r in ok if "in_sample" in r])
        for d in {r["direction"] for r in ok}:
            dr = [r for r in ok if r["direction"] == d]
            s[f"drift_rms_dph[{d}]"] = _stat([r.get("drift_rms_dph") for r in dr])
        bws = [b for b in ev.bandwidth if b["method"] == m and "error" not in b]
        for f in BANDWIDTH_FREQS_HZ:
            k = f"{f:g}"
            s[f"gain_{k}Hz"] = _stat([b["response"][k]["gain"] for b in bws])
            s[f"phase_{k}Hz_deg"] = _stat([b["response"][k]["phase_deg"] for b in bws])
        s["errors"] = sorted({r["error"] for r in runs if "error" in r}
                             | {b["error"] for b in ev.bandwidth if b["method"] == m and "error" in b})
        out[m] = s
    return out


# --------------------------------------------------------------------------------------------
# Reports
# --------------------------------------------------------------------------------------------
def _fmt(st: dict | None, fmt: str = ".3g", show_n: bool = False) -> str:
    if not st or st.get("mean") is None:
        return "n/a" if not st or not st.get("n_total") else f"not valid (0/{st['n_total']})"
    s = format(st["mean"], fmt)
    if st.get("sd") is not None:
        s += f" ± {format(st['sd'], fmt)}"
    if show_n and st["n"] < st["n_total"]:
        s += f" ({st['n']}/{st['n_total']} valid)"
    return s


def markdown_table(ev: Evaluation) -> str:
    """The comparison as Markdown: paper-way figures, honest figures and bandwidth.

    Parameters
    ----------
    ev : Evaluation

    Returns
    -------
    str
    """
    S = ev.summary
    lines = ["**Paper's way** (held-out run; N = Allan deviation at tau = 1 s whatever the slope, "
             "B = global Allan minimum)" + (" and in-sample (fitted and read on the training run, as the papers did)"
                                             if ev.config.get("in_sample") else ""), "",
             "| method | N paper-way (deg/h/√Hz) | N paper-way (deg/√h) | slope at 1 s | B paper-way (deg/h)"
             + (" | in-sample N (deg/h/√Hz) | in-sample B (deg/h)" if ev.config.get("in_sample") else "") + " |",
             "|---|---|---|---|---" + ("|---|---" if ev.config.get("in_sample") else "") + "|"]
    for m, s in S.items():
        row = (f"| {m} | {_fmt(s['N_paper_dph_rtHz'], '.4g')} | {_fmt(s['N_paper_deg_rt_h'], '.3g')} | "
               f"{_fmt(s['slope_at_1s'], '+.2f')} | {_fmt(s['B_paper_dph'], '.3g')}")
        if ev.config.get("in_sample"):
            row += f" | {_fmt(s.get('in_sample_N_paper_dph_rtHz'), '.4g')} | {_fmt(s.get('in_sample_B_paper_dph'), '.3g')}"
        lines.append(row + " |")
    lines += ["", "**Honest figures** (held-out run: other seed and other temperature profile; "
              "N only on a -1/2 ± 0.1 region; B at tau ≥ 10 × the filter time constant)", "",
              "| method | filter τ (s) | N valid (deg/√h) | B valid (deg/h) | truth RMS (deg/h) | "
              "truth max (deg/h) | 100 s drift RMS (deg/h) | 100 s drift max (deg/h) | bias/°C (deg/h/°C) |",
              "|---|---|---|---|---|---|---|---|---|"]
    for m, s in S.items():
        lines.append(f"| {m} | {_fmt(s['filter_time_constant_s'], '.3g')} | {_fmt(s['N_valid_deg_rt_h'], '.3g', True)} | "
                     f"{_fmt(s['B_valid_dph'], '.3g')} | {_fmt(s['rms_dph'], '.4g')} | {_fmt(s['max_dph'], '.4g')} | "
                     f"{_fmt(s['drift_rms_dph'], '.3g')} | {_fmt(s['drift_max_dph'], '.3g')} | "
                     f"{_fmt(s['bias_per_C_dph'], '.3g')} |")
    if ev.config.get("bandwidth"):
        lines += ["", "**Bandwidth** (rate table, method fitted on an oven run at the same rate; "
                  "gain = |compensated| / |true| at f, phase of compensated vs true)", "",
                  "| method | gain 1 Hz | gain 10 Hz | gain 50 Hz | phase 1 Hz (deg) | phase 10 Hz (deg) | phase 50 Hz (deg) |",
                  "|---|---|---|---|---|---|---|"]
        for m, s in S.items():
            lines.append(f"| {m} | " + " | ".join(_fmt(s[f'gain_{f:g}Hz'], '.3f') for f in BANDWIDTH_FREQS_HZ) + " | "
                         + " | ".join(_fmt(s[f'phase_{f:g}Hz_deg'], '.1f') for f in BANDWIDTH_FREQS_HZ) + " |")
    errs = [(m, e) for m, s in S.items() for e in s["errors"]]
    if errs:
        lines += ["", "**Failures**", ""] + [f"- {m}: {e}" for m, e in errs]
    c = ev.config
    lines += ["", f"Mean ± SD over {c['seeds']} seeds × {len(c['directions'])} directions "
              f"({', '.join(c['directions'])}) for held-out figures, over {c['seeds']} seeds for bandwidth. "
              f"Effects on: {c['effects']}."]
    return "\n".join(lines) + "\n"


#: The papers' own figures of their methods, read their way (paper 000 Table 2: N in deg/h/sqrt(Hz), B in
#: deg/h; paper 004: ARW in deg/sqrt(h), B in deg/h), by the project's method name.
PAPER_FIGURES = {
    "paper 000, Table 2": ("N", {RAW: (99.608, 34.66), "emd-rbf": (99.6037, 28.42), "emd-rbf-ga": (99.6011, 23.65),
                                 "emd-rbf-ga-kf": (0.967814, 3.589)}),
    "paper 004": ("ARW", {RAW: (1.667, 30.0), "vmd-wflp-cssvr": (0.0667, 4.0)}),
}


def papers_table(ev: Evaluation) -> str:
    """The papers' figures beside ours read the papers' way, as Markdown.

    Parameters
    ----------
    ev : Evaluation

    Returns
    -------
    str
    """
    S = ev.summary
    lines = ["| | paper's own | ours, paper's way (held-out, mean ± SD) | slope of the Allan curve at τ = 1 s (ours) |",
             "|---|---|---|---|"]
    for paper, (kind, rows) in PAPER_FIGURES.items():
        unit = "N in deg/h/√Hz" if kind == "N" else "ARW in deg/√h"
        lines.append(f"| **{paper}** ({unit}, B in deg/h) | | | |")
        for m, (n, b) in rows.items():
            if m not in S:
                continue
            key = "N_paper_dph_rtHz" if kind == "N" else "N_paper_deg_rt_h"
            lines.append(f"| `{m}` | {kind} {n:g}, B {b:g} | {kind} {_fmt(S[m][key])}, B {_fmt(S[m]['B_paper_dph'])} | "
                         f"{_fmt(S[m]['slope_at_1s'], '+.2f')} |")
    return "\n".join(lines) + "\n"


def plot_allan(ev: Evaluation, path, direction: str | None = None) -> None:
    """Allan curves before (raw) and after each method on the first seed's held-out run.

    Parameters
    ----------
    ev : Evaluation
    path : path-like
        PNG to write.
    direction : str, optional
        Which direction (default: the first).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    direction = direction or ev.config["directions"][0]
    methods = [m for m in ev.config["methods"] if (m, direction) in ev.curves]
    raw = ev.curves.get((RAW, direction))
    n = max(1, len(methods))
    ncol = min(4, n)
    nrow = math.ceil(n / ncol)
    fig = Figure(figsize=(3.6 * ncol, 3.0 * nrow))
    FigureCanvasAgg(fig)
    for i, m in enumerate(methods):
        ax = fig.add_subplot(nrow, ncol, i + 1)
        c = ev.curves[(m, direction)]
        if raw is not None:
            ax.loglog(raw["taus_s"], raw["adev_dph"], color="0.6", lw=1.2, label="raw")
        ax.loglog(c["taus_s"], c["adev_dph"], color="C0", lw=1.5, label=m)
        if c["tau_filter_s"] > 0:
            ax.axvspan(min(c["taus_s"]), TAU_FACTOR * c["tau_filter_s"], color="C3", alpha=0.08,
                       label="τ < 10×filter τ")
        ax.axvline(1.0, color="k", lw=0.5, ls=":")
        ax.set_title(m, fontsize=9)
        ax.set_xlabel("τ (s)", fontsize=8)
        ax.set_ylabel("σ(τ) (deg/h)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6)
    fig.suptitle(f"Allan deviation on the held-out run ({direction}, seed {ev.config['seed_offset']})", fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def plot_traces(ev: Evaluation, path, direction: str | None = None) -> None:
    """Compensated minus true rate (10 s means) over the held-out run, and a rate-table window.

    Parameters
    ----------
    ev : Evaluation
    path : path-like
    direction : str, optional
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    direction = direction or ev.config["directions"][0]
    methods = [m for m in ev.config["methods"] if (m, direction) in ev.curves]
    fig = Figure(figsize=(11, 7.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(2, 1, 1)
    for i, m in enumerate(methods):
        c = ev.curves[(m, direction)]
        ax.plot(c["t10"] / 3600.0, c["err10_dph"], lw=0.9, color=f"C{i}", label=m,
                alpha=0.5 if m == RAW else 1.0)
    ax.set_xlabel("time (h)")
    ax.set_ylabel("compensated − true (deg/h, 10 s means)")
    ax.set_title(f"Held-out run {direction}, seed {ev.config['seed_offset']} (true rate 0)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=4)
    lo = [np.percentile(ev.curves[(m, direction)]["err10_dph"], 1) for m in methods if m != RAW]
    hi = [np.percentile(ev.curves[(m, direction)]["err10_dph"], 99) for m in methods if m != RAW]
    if lo:
        span = max(abs(min(lo)), abs(max(hi)))
        ax.set_ylim(-3 * span, 3 * span)
    ax.axhline(0, color="k", lw=0.5)
    if any(k[1] == "rate_table" for k in ev.curves):
        for j, f in enumerate(("1", "10")):
            ax2 = fig.add_subplot(2, 2, 3 + j)
            first = True
            for i, m in enumerate(methods):
                c = ev.curves.get((m, "rate_table"), {})
                c = ({"1": c} if "t" in c else c).get(f)  # older single-window format
                if c is None:
                    continue
                if first:
                    ax2.plot(c["t"], c["true"], color="k", lw=2.0, label="true rate")
                    first = False
                ax2.plot(c["t"], c["out"], lw=0.8, color=f"C{i}", label=m, alpha=0.8)
            ax2.set_xlabel("time (s)")
            ax2.set_ylabel("rate (deg/s)")
            ax2.set_title(f"Rate table, 10 deg/s at {f} Hz (fitted on an oven run)", fontsize=9)
            ax2.grid(True, alpha=0.3)
            if not first:
                ax2.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    _save(fig, path)


def plot_summary(ev: Evaluation, path) -> None:
    """Bar chart: B paper-way vs honest B and the held-out 100 s drift RMS, per method.

    Parameters
    ----------
    ev : Evaluation
    path : path-like
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    S = ev.summary
    ms = list(S)
    fig = Figure(figsize=(11, 4.2))
    FigureCanvasAgg(fig)
    x = np.arange(len(ms))

    def vals(k):
        return (np.array([S[m][k]["mean"] if S[m][k]["mean"] is not None else np.nan for m in ms]),
                np.array([S[m][k]["sd"] if S[m][k]["sd"] is not None else 0.0 for m in ms]))

    ax = fig.add_subplot(1, 3, 1)
    for j, (k, lab) in enumerate((("B_paper_dph", "paper-way (global min)"), ("B_valid_dph", "τ ≥ 10×filter τ"))):
        v, e = vals(k)
        ax.bar(x + (j - 0.5) * 0.38, v, 0.38, yerr=e, label=lab)
    ax.set_yscale("log")
    ax.set_title("bias instability (deg/h)", fontsize=9)
    ax.legend(fontsize=7)
    ax2 = fig.add_subplot(1, 3, 2)
    for j, (k, lab) in enumerate((("N_paper_deg_rt_h", "paper-way (σ at 1 s)"), ("N_valid_deg_rt_h", "-1/2 region only"))):
        v, e = vals(k)
        ax2.bar(x + (j - 0.5) * 0.38, v, 0.38, yerr=e, label=lab)
    ax2.set_yscale("log")
    ax2.set_title("ARW (deg/√h); missing bar = not valid", fontsize=9)
    ax2.legend(fontsize=7)
    ax3 = fig.add_subplot(1, 3, 3)
    v, e = vals("drift_rms_dph")
    ax3.bar(x, v, 0.6, yerr=e, color="C2")
    ax3.set_yscale("log")
    ax3.set_title("held-out 100 s drift RMS (deg/h)", fontsize=9)
    for a in (ax, ax2, ax3):
        a.set_xticks(x)
        a.set_xticklabels(ms, rotation=40, ha="right", fontsize=7)
        a.grid(True, axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    _save(fig, path)


def _save(fig, path) -> None:
    import os
    import tempfile
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".png", dir=path.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
