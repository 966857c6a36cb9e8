"""A record made ready for diagnosis: checks, gaps and NaNs, the model's inputs, blocks, regimes, folds.

The forward model is fitted on *blocks* (default 10 s means of every channel): the effects are
slow, a block mean keeps all their information, and 13 h become ~5000 rows. The model's inputs
(die-temperature path, applied rate) are computed at the full rate and block-averaged the same way.

Each record sample is an integrate-and-dump mean over the interval that ends at its time stamp
(docs/formats.md section 2, both engines), so the model is evaluated at interval centres.

A channel whose samples sit on a lattice (a converter coarser than its noise) carries the
quantiser's staircase into every block mean; that is a floor on the block sigma
(:meth:`Prepared.quantization_floor`), and the null replicates are read through the same lattice.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import savgol_filter

from ..errors import InputError
from ..record import Record
from .forward import CHANNELS

#: Fitting block length (s).
BLOCK_S = 10.0
#: Number of equal time segments; the last ``N_FOLDS`` are the forward-chained held-out blocks.
N_SEGMENTS = 5
N_FOLDS = 3
#: Gap between a fold's training data and its held-out block, as a fraction of a segment.
GAP_FRACTION = 0.2
#: Samples this close to rate-table motion are left out of the noise statistics (s).
RATE_MARGIN_S = 30.0
#: Shortest record the windows allow (s).
MIN_DURATION_S = 3600.0
#: Held-out temperatures farther than this outside a training window's range count as extrapolation (K).
COVERAGE_MARGIN_K = 0.5
#: |dT/dt| below which the oven is holding (K/min).
HOLD_K_PER_MIN = 0.05
#: Model-accuracy floors per block (quasi-static model against the envelope engine, see the tests).
FLOORS = {"rate_V": 2e-7, "quadrature_V": 2e-6, "drive_amplitude_V": 3e-7, "agc_effort_V": 1e-6,
          "drive_frequency_Hz": 3e-5}
#: A channel is quantised when this fraction of its samples sits on the lattice found.
ON_LATTICE_MIN = 0.9
#: Channels read through one converter (the output quantiser acts on both).
CONVERTER_CHANNELS = ("rate_V", "quadrature_V")


def difference_sigma(x: np.ndarray, empty: float = float("nan")) -> float:
    """Per-sample white-noise level of a series from its first differences (robust: MAD, NaNs skipped).

    Parameters
    ----------
    x : ndarray
    empty : float, optional
        Returned when there is no finite difference.

    Returns
    -------
    float
    """
    d = np.diff(np.asarray(x, dtype=float))
    d = d[np.isfinite(d)]
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2)) if d.size else empty


def lattice_lsb(x_V: np.ndarray) -> tuple[float, float]:
    """Spacing of the lattice a quantised signal lives on, and the fraction of samples on it.

    Parameters
    ----------
    x_V : ndarray

    Returns
    -------
    lsb : float
        0 when no lattice is found.
    on_lattice : float
        Fraction of samples within 2 % of an lsb of the lattice.
    """
    x = np.asarray(x_V, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) < 100:
        return 0.0, 0.0
    d = np.abs(np.diff(x))
    d = d[d > 1e-12 * max(np.max(np.abs(x)), 1e-30)]
    if not len(d):
        return 0.0, 0.0
    q = np.quantile(d, 0.02)
    small = d[d < 1.5 * q]
    lsb = float(np.median(small))
    if lsb <= 0:
        return 0.0, 0.0
    return lsb, on_lattice(x, lsb)


def lattice_offset(x_V: np.ndarray, lsb_V: float) -> float:
    """Where the lattice of step ``lsb_V`` a signal lives on passes, ``offset + k * lsb_V``: the circular mean of the
    samples' phase on it. A converter's lattice passes through its zero, but an offset the data acquisition adds after
    it (a DAQ zero, a subtracted bias) shifts it by any fraction of a step.

    Parameters
    ----------
    x_V : ndarray
    lsb_V : float

    Returns
    -------
    float
        In ``[0, lsb_V)``; 0 without finite samples.
    """
    x = np.asarray(x_V, dtype=float)
    x = x[np.isfinite(x)]
    if not len(x) or not lsb_V > 0:
        return 0.0
    z = np.mean(np.exp(2j * np.pi * (x / lsb_V)))
    return float(np.mod(np.angle(z) / (2 * np.pi), 1.0) * lsb_V) if abs(z) > 0 else 0.0


def on_lattice(x_V: np.ndarray, lsb_V: float, offset_V: float | None = None) -> float:
    """Fraction of the finite samples within 2 % of a step of the lattice ``offset_V + k * lsb_V``.

    Parameters
    ----------
    x_V : ndarray
    lsb_V : float
    offset_V : float, optional
        Where the lattice passes; default the samples' own (:func:`lattice_offset`).

    Returns
    -------
    float
    """
    x = np.asarray(x_V, dtype=float)
    x = x[np.isfinite(x)]
    if not len(x):
        return 0.0
    off = lattice_offset(x, lsb_V) if offset_V is None else offset_V
    u = (x - off) / lsb_V
    return float(np.mean(np.abs(u - np.round(u)) < 0.02))


@dataclass
class Prepared:
    """A record ready for the diagnosis.

    Attributes
    ----------
    t_s : ndarray
        Sample times from the first sample's interval start (s).
    t_mid_s : ndarray
        Interval centres (where the model is evaluated).
    case_C : ndarray
        Sensor temperature at the interval centres, gap-free (interpolated over NaNs), smoothed if noisy.
    rate_true_dps : ndarray
    obs : dict
        Channel -> ndarray (NaN where missing); ``rate_V`` is derived from ``rate_dps`` when absent.
    channels : tuple
        Channels present (with finite samples).
    sf_nominal_V_per_dps : float
        The scale factor that converts ``rate_V`` to ``rate_dps``.
    sample_interval_s : float
    block : ndarray of int
        Block index of each sample.
    n_blocks : int
    issues : dict
        Gaps and NaNs found and how they were handled.
    dTdt_K_per_min : ndarray
        Smoothed case-temperature rate.
    """

    t_s: np.ndarray
    t_mid_s: np.ndarray
    case_C: np.ndarray
    rate_true_dps: np.ndarray
    obs: dict
    channels: tuple
    sf_nominal_V_per_dps: float
    sample_interval_s: float
    block: np.ndarray
    n_blocks: int
    issues: dict
    dTdt_K_per_min: np.ndarray
    case_at_t_C: np.ndarray
    start_s: float
    path: str = ""
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def duration_s(self) -> float:
        """Record span (s)."""
        return float(self.t_s[-1] - self.t_s[0] + self.sample_interval_s)

    def block_mean(self, x: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
        """Mean of a full-rate signal in each block (NaN where a block has no valid sample).

        Parameters
        ----------
        x : ndarray
        valid : ndarray of bool, optional

        Returns
        -------
        ndarray, shape (n_blocks,)
        """
        x = np.asarray(x, dtype=float)
        ok = np.isfinite(x) if valid is None else (valid & np.isfinite(x))
        n = np.bincount(self.block[ok], minlength=self.n_blocks)
        s = np.bincount(self.block[ok], weights=x[ok], minlength=self.n_blocks)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n > 0, s / np.maximum(n, 1), np.nan)

    def block_counts(self, ch: str) -> np.ndarray:
        """Finite samples of channel ``ch`` per block.

        Parameters
        ----------
        ch : str

        Returns
        -------
        ndarray
        """
        key = ("n", ch)
        if key not in self._cache:
            ok = np.isfinite(self.obs[ch])
            self._cache[key] = np.bincount(self.block[ok], minlength=self.n_blocks)
        return self._cache[key]

    def block_obs(self) -> np.ndarray:
        """Block means of the observed channels, shape (n_blocks, len(CHANNELS)), NaN where absent.

        Returns
        -------
        ndarray
        """
        if "obs" not in self._cache:
            Y = np.full((self.n_blocks, len(CHANNELS)), np.nan)
            for i, c in enumerate(CHANNELS):
                if c in self.channels:
                    Y[:, i] = self.block_mean(self.obs[c])
            self._cache["obs"] = Y
        return self._cache["obs"]

    def block_time_s(self) -> np.ndarray:
        """Mean time of each block (s)."""
        if "t" not in self._cache:
            self._cache["t"] = self.block_mean(self.t_mid_s)
        return self._cache["t"]

    def white_sigma(self) -> np.ndarray:
        """Per-sample white-noise level of each channel from first differences (robust), shape (C,).

        Returns
        -------
        ndarray
        """
        if "sig" not in self._cache:
            s = np.full(len(CHANNELS), np.nan)
            for i, c in enumerate(CHANNELS):
                if c in self.channels:
                    s[i] = difference_sigma(self.obs[c])
            self._cache["sig"] = s
        return self._cache["sig"]

    def lattice_of(self, ch: str) -> tuple[float, float]:
        """Lattice spacing of channel ``ch`` and the fraction of its samples on it (:func:`lattice_lsb`).

        Parameters
        ----------
        ch : str

        Returns
        -------
        lsb, on_lattice : float
        """
        key = ("lattice", ch)
        if key not in self._cache:
            self._cache[key] = lattice_lsb(self.obs[ch]) if ch in self.channels else (0.0, 0.0)
        return self._cache[key]

    def lattice_offsets(self) -> np.ndarray:
        """Where each channel's lattice passes (:func:`lattice_offset`; 0 where there is no lattice), shape (C,).

        Returns
        -------
        ndarray
        """
        if "lattice_offsets" not in self._cache:
            L = self.lattice()
            self._cache["lattice_offsets"] = np.array([lattice_offset(self.obs[c], L[i]) if L[i] > 0 else 0.0
                                                       for i, c in enumerate(CHANNELS)])
        return self._cache["lattice_offsets"].copy()

    def lattice(self) -> np.ndarray:
        """The recorder's resolution per channel (0 where the samples are not on a lattice), shape (C,).

        Returns
        -------
        ndarray
        """
        out = np.zeros(len(CHANNELS))
        for i, c in enumerate(CHANNELS):
            lsb, frac = self.lattice_of(c)
            if frac >= ON_LATTICE_MIN:
                out[i] = lsb
        # one converter reads rate and quadrature: a channel that never leaves one level has its signal
        # and noise inside half a step (no lattice to read off it), and takes the step the other one shows
        conv = [CHANNELS.index(c) for c in CONVERTER_CHANNELS if c in self.channels]
        step = max((out[i] for i in conv), default=0.0)
        for i in conv:
            x = self.obs[CHANNELS[i]]
            x = x[np.isfinite(x)]
            if out[i] == 0.0 and step > 0 and len(x) and np.ptp(x) == 0.0:
                out[i] = step
        return out

    def quantization_floor(self) -> np.ndarray:
        """Block-mean error a coarse recorder leaves, per channel, shape (C,).

        A slowly varying signal read through a quantiser of step ``L`` has a deterministic staircase
        error (a sawtooth of the signal, rms ``L / sqrt(12)``) that a block mean does not average
        away; noise dithers it, attenuating its fundamental by ``exp(-2 pi^2 sigma^2 / L^2)``. The
        smooth forward model cannot follow the staircase, so the error is a floor on its accuracy.

        Returns
        -------
        ndarray
        """
        L = self.lattice()
        ws = np.nan_to_num(self.white_sigma())
        out = np.zeros_like(L)
        q = L > 0
        out[q] = L[q] / np.sqrt(12.0) * np.exp(-2.0 * np.pi ** 2 * ws[q] ** 2 / L[q] ** 2)
        return out

    def block_sigma(self) -> np.ndarray:
        """Noise level of each block mean: white level / sqrt(n) combined with the model and recorder floors.

        Returns
        -------
        ndarray, shape (n_blocks, C)
        """
        if "bsig" not in self._cache:
            ws = self.white_sigma()
            qf = self.quantization_floor()
            S = np.full((self.n_blocks, len(CHANNELS)), np.nan)
            for i, c in enumerate(CHANNELS):
                if c in self.channels:
                    n = np.maximum(self.block_counts(c), 1)
                    S[:, i] = np.sqrt(ws[i] ** 2 / n + FLOORS[c] ** 2 + qf[i] ** 2)
            self._cache["bsig"] = S
        return self._cache["bsig"]

    def regimes(self) -> dict:
        """Sample masks of the temperature regimes.

        Returns
        -------
        dict
            ``hold``, ``heating``, ``cooling``, ``ramp``, ``post_ramp_hold`` (first 30 min of a hold
            after a ramp), ``settled_hold``.
        """
        if "reg" not in self._cache:
            r = self.dTdt_K_per_min
            hold = np.abs(r) < HOLD_K_PER_MIN
            heat, cool = r >= HOLD_K_PER_MIN, r <= -HOLD_K_PER_MIN
            ramp = heat | cool
            # time since the last ramp sample
            last = np.where(ramp, self.t_s, np.nan)
            idx = np.arange(len(last))
            have = np.where(ramp, idx, 0)
            np.maximum.accumulate(have, out=have)
            since = self.t_s - self.t_s[have]
            ever = np.maximum.accumulate(ramp)
            post = hold & ever & (since < 1800.0)
            self._cache["reg"] = dict(hold=hold, heating=heat, cooling=cool, ramp=ramp, post_ramp_hold=post,
                                      settled_hold=hold & ~post)
        return self._cache["reg"]

    def block_regime(self, name: str) -> np.ndarray:
        """Blocks whose samples are mostly in regime ``name``.

        Parameters
        ----------
        name : str

        Returns
        -------
        ndarray of bool
        """
        return self.block_mean(self.regimes()[name].astype(float)) > 0.5

    def folds(self) -> list[dict]:
        """Forward-chained folds over blocks: train on everything before a gap, test on the next segment.

        Returns
        -------
        list of dict
            ``train`` and ``test`` boolean block masks, and the segment bounds in seconds.
        """
        tb = self.block_time_s()
        t0, t1 = self.t_s[0] - self.sample_interval_s, self.t_s[-1]
        seg = (t1 - t0) / N_SEGMENTS
        out = []
        for j in range(N_SEGMENTS - N_FOLDS, N_SEGMENTS):
            start, end = t0 + j * seg, t0 + (j + 1) * seg
            out.append(dict(train=tb < start - GAP_FRACTION * seg, test=(tb >= start) & (tb < end + 1e-9),
                            test_start_s=float(start), test_end_s=float(end)))
        return out

    def static_rate_samples(self, margin_s: float = RATE_MARGIN_S) -> np.ndarray:
        """Samples with no applied rate, at least ``margin_s`` away from any rate-table motion.

        Noise statistics (Allan bands) are read here: a rate step multiplies any scale-factor error
        into the residual and would swamp a noise-level effect.

        Parameters
        ----------
        margin_s : float, optional

        Returns
        -------
        ndarray of bool
        """
        key = ("static", margin_s)
        if key not in self._cache:
            moving = np.abs(self.rate_true_dps) > 0
            if moving.any():
                k = max(int(round(margin_s / self.sample_interval_s)), 0)
                grown = np.convolve(moving.astype(float), np.ones(2 * k + 1), mode="same") > 0
                self._cache[key] = ~grown
            else:
                self._cache[key] = np.ones(len(self.t_s), bool)
        return self._cache[key]

    def heldout_mask_samples(self) -> np.ndarray:
        """Samples in the held-out segments.

        Returns
        -------
        ndarray of bool
        """
        f = self.folds()
        return self.t_s >= f[0]["test_start_s"]

    def temperature_coverage(self, margin_K: float = COVERAGE_MARGIN_K) -> dict:
        """Temperatures each fold trains and is tested on, and how far its held-out segment leaves them.

        A temperature law fitted on one range and scored beyond it is scored on its extrapolation as
        much as on the effect: the report says where that happens.

        Parameters
        ----------
        margin_K : float, optional
            Held-out blocks more than this outside their fold's training range count as outside it.

        Returns
        -------
        dict
            ``record_C`` ([min, max] of the block-mean sensor temperature), ``heldout_outside_fraction``
            and ``heldout_outside_max_K`` (held-out blocks outside the training range of their fold),
            ``margin_K``, and ``folds``: per fold ``train_C``, ``test_C``, ``test_outside_fraction`` and
            ``test_outside_max_K``.
        """
        T = self.block_mean(self.case_C)
        ok = np.isfinite(T)

        def span(m):
            v = T[m & ok]
            return [float(v.min()), float(v.max())] if v.size else None

        per_fold, excess = [], []
        for fd in self.folds():
            tr, v = span(fd["train"]), T[fd["test"] & ok]
            ex = np.maximum(np.maximum(tr[0] - v, v - tr[1]), 0.0) if tr is not None else np.zeros(0)
            excess.append(ex)
            per_fold.append({"train_C": tr, "test_C": span(fd["test"]),
                             "test_outside_fraction": float(np.mean(ex > margin_K)) if ex.size else 0.0,
                             "test_outside_max_K": float(ex.max()) if ex.size else 0.0})
        ex = np.concatenate(excess)
        return {"record_C": span(np.ones(self.n_blocks, bool)), "margin_K": float(margin_K),
                "heldout_outside_fraction": float(np.mean(ex > margin_K)) if ex.size else 0.0,
                "heldout_outside_max_K": float(ex.max()) if ex.size else 0.0, "folds": per_fold}


def prepare(record: Record, sf_nominal_V_per_dps: float, block_s: float = BLOCK_S) -> Prepared:
    """Check a record and make it ready for the diagnosis.

    Parameters
    ----------
    record : Record
        From :func:`fmvmg_sim.record.read_record` (columns and monotonic time already checked).
    sf_nominal_V_per_dps : float
        The scenario device's nominal scale factor (converts ``rate_dps`` to ``rate_V``).
    block_s : float, optional

    Returns
    -------
    Prepared

    Raises
    ------
    InputError
        Too short, no finite temperature or rate, or a rate column inconsistent with ``rate_V``.
    """
    name = record.path or "record"
    t = np.asarray(record.time_s, dtype=float)
    if len(t) < 10:
        raise InputError(f"only {len(t)} samples; the diagnosis needs at least {MIN_DURATION_S:.0f} s of data", name)
    dts = np.diff(t)
    dt = float(np.median(dts))
    span = float(t[-1] - t[0] + dt)
    if span < MIN_DURATION_S:
        raise InputError(f"the record spans {span:.0f} s; the diagnosis needs at least {MIN_DURATION_S:.0f} s "
                         f"(a training window plus {N_FOLDS} forward-chained held-out blocks, each after a gap)", name)
    issues: dict = {"nan_samples": {}, "gaps": []}
    big = np.flatnonzero(dts > 1.5 * dt)
    for k in big:
        issues["gaps"].append({"after_s": float(t[k]), "length_s": float(dts[k])})
    issues["gap_total_s"] = float(np.sum(dts[big] - dt)) if big.size else 0.0
    for c in ("temperature_C", "rate_dps", *CHANNELS, "rate_true_dps"):
        if c in record.columns:
            n = int(np.sum(~np.isfinite(record[c])))
            if n:
                issues["nan_samples"][c] = n
    temp = np.asarray(record["temperature_C"], dtype=float)
    okT = np.isfinite(temp)
    if okT.sum() < 2:
        raise InputError("temperature_C has fewer than 2 finite samples", name)
    if not np.isfinite(record["rate_dps"]).any():
        raise InputError("rate_dps has no finite sample", name)
    temp = np.interp(t, t[okT], temp[okT])  # NaNs bridged linearly (reported in issues)
    # a sensor reading with noise is smoothed (Savitzky-Golay, 60 s window fixed in advance), on an even time
    # grid so that a gap in the record does not bend the temperature on either side of it
    d2 = np.diff(temp, 2)
    win = int(round(60.0 / dt)) | 1
    t_even = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    noisy = len(t_even) > win > 3 and np.median(np.abs(d2)) > 1e-6
    if noisy:
        temp_s = np.interp(t, t_even, savgol_filter(np.interp(t_even, t, temp), win, 2, mode="interp"))
        issues["temperature_smoothed_window_s"] = win * dt
    else:
        temp_s = temp
    start = t[0] - dt
    t_rel = t - start
    # each sample is a mean over its own sampling interval: after a gap (missing samples), not over the gap
    first = np.minimum(np.concatenate([[dt], dts]), dt)
    t_mid = t_rel - 0.5 * first
    case_mid = np.interp(t_mid, t_rel, temp_s, left=temp_s[0])
    rate_true = np.nan_to_num(np.asarray(record.columns.get("rate_true_dps", np.zeros_like(t)), dtype=float))
    # the applied rate is read at the sample times while the outputs are means over each sample's
    # interval: evaluate it at the interval centres (else every rate step leaves half a sample of
    # full-scale rate in the residual, which the calibration then bends the nominal knobs to absorb)
    rate_true_mid = np.interp(t_mid, t_rel, rate_true, left=rate_true[0]) if len(rate_true) > 1 else rate_true
    obs = {}
    for c in CHANNELS:
        if c in record.columns and np.isfinite(record[c]).any():
            obs[c] = np.asarray(record[c], dtype=float)
    if "rate_V" not in obs:
        obs["rate_V"] = np.asarray(record["rate_dps"], dtype=float) * sf_nominal_V_per_dps
        issues["rate_V_derived"] = True
    chans = tuple(c for c in CHANNELS if c in obs)
    nb_time = max(1, int(round(block_s / dt)))
    block_s = nb_time * dt
    blk = np.floor((t_rel - 1e-9 * dt) / block_s).astype(int)
    _, blk = np.unique(blk, return_inverse=True)  # drop empty blocks (gaps)
    dTdt = np.gradient(temp_s, t_rel) * 60.0
    if len(t_even) > win > 3:
        dTdt = np.interp(t, t_even, savgol_filter(np.interp(t_even, t, dTdt), win, 1, mode="interp"))
    return Prepared(t_rel, t_mid, case_mid, rate_true_mid, obs, chans, float(sf_nominal_V_per_dps), dt,
                    blk, int(blk.max()) + 1, issues, dTdt, temp_s, float(start), name)
