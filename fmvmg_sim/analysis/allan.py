"""Overlapping Allan deviation of a rate signal and the IEEE 952 noise terms read from it.

The deviation is allantools' ``oadev(data_type='freq', rate=fs, taus=...)`` (checked against
Stable32 and NIST SP 1065 values in the tests); :func:`oadev_numpy` is a short independent
implementation kept as a cross-check.

Confidence intervals
--------------------
Chi-square intervals with Greenhall's equivalent degrees of freedom (Greenhall & Riley 2004,
``allantools.edf_greenhall(d=2, overlapping=True)`` then ``allantools.confidence_interval``; this
reproduces Stable32's "Min Sigma / Max Sigma" columns). The EDF needs the power-law noise type
alpha (S_y ~ f^alpha) at each tau. It is identified with the lag-1 autocorrelation method
(Riley & Greenhall 2004, Stable32's default) on the tau-averaged series wherever at least 100
averages exist (standard error of the lag-1 ACF <= 0.1); at longer taus it is read from the local
slope mu of the curve, alpha = round(-2 mu - 1) clipped to -2..1. Where Greenhall's EDF is
undefined (white PM at the very longest taus) Stein's simple EDF is used.

Noise terms (IEEE Std 952-1997, Annex C)
----------------------------------------
The local log-log slope at each tau is the least-squares slope of ln(sigma) on ln(tau) over the
points within one octave either side. Only points averaging at least ``min_clusters``
independent clusters (N // m) are used for fits and the minimum.

* ARW: read only where a white-noise region exists: the shortest-tau run of points whose local
  slope is -1/2 +- 0.1, spanning at least one octave and lying at or left of the Allan minimum.
  No run, no N (None, with a reason): N is never read outside a valid region. N is then the
  white term of the power-law sum ``sigma^2 = C/tau^2 + N^2/tau + B^2 + K^2 tau/3`` (IEEE 952
  Annex C) fitted, EDF-weighted, from the start of the run to the Allan minimum: the flicker
  floor's bend towards the minimum is the ``B^2`` term's, not the white line's; the leading
  deficit of a low-pass (an anti-alias or output filter, which lowers sigma by about
  ``tau_f / tau`` relative: 9 % at tau = 10 ms behind a 100 Hz two-pole filter) and any
  quantisation are the ``C/tau^2`` term's. The taus the filter shapes beyond that leading term
  (within a few of its time constants) are left out: the fit starts at the shortest tau of the
  run from which the sum fits every fitted point within :data:`FIT_SIGMAS` of its confidence
  interval. So N is the white level itself, the same from records of one noise at 10 Hz or 1 kHz.
* Bias instability: the Allan minimum, min over usable taus of sigma ("Allan minimum"
  definition, the one paper 000's 34.66 deg/h uses); the IEEE 952 flicker coefficient
  B = minimum / 0.664 is reported separately.
* RRW: sigma = K sqrt(tau / 3) fitted on the longest-tau +1/2 +- 0.1 run right of the minimum; K is
  the line at tau = 3 s.
* Quantisation: sigma = sqrt(3) Q / tau fitted on a -1 +- 0.1 run left of the minimum; Q is the
  line at tau = sqrt(3) s.

Units: the input is a rate in the channel's own unit (deg/s for ``rate_dps``). The
``*_deg_*`` terms assume deg/s: N[deg/sqrt(h)] = N[deg/s*sqrt(s)] * 60,
B[deg/h] = sigma[deg/s] * 3600, K[deg/h/sqrt(h)] = K[deg/s/sqrt(s)] * 216000. For another unit
they are None and the generic ``N``, ``allan_minimum`` and ``K`` (in that unit) carry the values.
"""

from __future__ import annotations

import contextlib
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import allantools
import numpy as np
from scipy.optimize import lsq_linear

from ..errors import InputError

#: One-sigma (68.27 %) confidence level, Stable32's default.
CI_ONE_SIGMA = 0.6826894921370859
#: IEEE 952 bias-instability factor sqrt(2 ln2 / pi): B = sigma_min / 0.664.
BI_IEEE952_FACTOR = 0.664
#: deg/s*sqrt(s) -> deg/sqrt(h).
ARW_TO_DEG_PER_SQRT_H = 60.0
#: deg/s -> deg/h.
RATE_TO_DEG_PER_H = 3600.0
#: deg/s/sqrt(s) -> deg/h/sqrt(h).
RRW_TO_DEG_PER_H_SQRT_H = 3600.0 * 60.0
#: deg/s/sqrt(s) -> deg/h/sqrt(s).
RRW_TO_DEG_PER_H_SQRT_S = 3600.0
#: Slope tolerance of a fit region (IEEE 952 reads each term on its own slope).
SLOPE_TOL = 0.1
#: Averages needed before the lag-1 autocorrelation noise identification is trusted.
NOISE_ID_MIN_AVERAGES = 100
#: A start tau of the ARW fit is accepted when the power-law sum fits every fitted point within this many
#: one-sigma confidence half-widths (in ln sigma); shorter, filter-shaped taus do not.
FIT_SIGMAS = 2.0
#: The fit is judged over its first taus, up to this multiple of its start (a filter's shaping shows there;
#: the statistical wiggles of the flicker floor towards the Allan minimum must not move the start).
SHAPED_SPAN = 4.0
#: Label of the ARW reading used for ``arw_deg_per_sqrt_h``.
ARW_DEFINITION = ("white term N of the power-law sum C/tau^2 + N^2/tau + B^2 + K^2 tau/3 fitted from the first "
                  "unshaped tau of the -1/2 region to the Allan minimum (IEEE 952 Annex C), read as N at tau = 1 s")
#: Label of the bias-instability definition used for ``bias_instability_deg_per_h``.
BI_DEFINITION = "allan_minimum: min over tau of the OADEV (no 0.664 factor); IEEE 952 B = min/0.664 is bias_instability_ieee952_deg_per_h"


def oadev_numpy(rate: np.ndarray, fs_Hz: float, m: np.ndarray) -> np.ndarray:
    """Overlapping Allan deviation in plain numpy (cross-check of allantools).

    Parameters
    ----------
    rate : array_like
        Evenly sampled rate ("frequency") data, any unit.
    fs_Hz : float
        Sample rate in Hz.
    m : array_like of int
        Averaging factors; tau = m / fs_Hz.

    Returns
    -------
    ndarray
        OADEV at each m, in the unit of ``rate`` (NIST SP 1065 eq. 11 on the integrated phase).
    """
    y = np.asarray(rate, dtype=float)
    x = np.concatenate(([0.0], np.cumsum(y - y.mean()))) / fs_Hz  # phase (rate integral)
    out = np.empty(len(m))
    for i, mi in enumerate(np.asarray(m, dtype=int)):
        d2 = x[2 * mi:] - 2.0 * x[mi:-mi] + x[:-2 * mi]
        out[i] = math.sqrt(np.mean(d2 * d2) / 2.0) * fs_Hz / mi
    return out


def averaging_factors(n_samples: int, taus: str | np.ndarray = "octave", fs_Hz: float = 1.0,
                      stop_ratio: int = 4, per_decade: int = 10) -> np.ndarray:
    """Averaging factors m (tau = m / fs) for an OADEV of ``n_samples`` rate samples.

    Parameters
    ----------
    n_samples : int
        Number of rate samples.
    taus : {"octave", "dense"} or array_like of float
        ``"octave"``: m = 1, 2, 4, ...; ``"dense"``: about ``per_decade`` log-spaced m per decade;
        an array: these taus in seconds (rounded to whole samples, duplicates removed).
    fs_Hz : float, optional
        Sample rate in Hz (used to convert explicit taus).
    stop_ratio : int, optional
        Automatic lists stop at m <= (n_samples + 1) / stop_ratio, Stable32's OADEV stop ratio.
    per_decade : int, optional
        Density of ``"dense"``.

    Returns
    -------
    ndarray of int
        Sorted unique averaging factors, each leaving at least two second differences.

    Raises
    ------
    InputError
        Unknown keyword, or too few samples for any tau.
    """
    n_phase = n_samples + 1
    if isinstance(taus, str):
        m_max = n_phase // stop_ratio
        if m_max < 1:
            raise InputError(f"{n_samples} samples are too few for an Allan deviation (need at least {stop_ratio})")
        if taus == "octave":
            m = 2 ** np.arange(int(math.floor(math.log2(m_max))) + 1)
        elif taus == "dense":
            m = np.round(np.logspace(0, math.log10(m_max), max(2, int(per_decade * math.log10(m_max)) + 1)))
        else:
            raise InputError(f"taus must be 'octave', 'dense' or a list of seconds, got {taus!r}")
    else:
        m = np.round(np.asarray(taus, dtype=float) * fs_Hz)
    m = np.unique(m.astype(np.int64))
    m = m[(m >= 1) & (n_phase - 2 * m >= 2)]
    if m.size == 0:
        raise InputError(f"no usable tau for {n_samples} samples at {fs_Hz:g} Hz")
    return m


def noise_alpha(rate: np.ndarray, m: int, dmax: int = 2) -> int | None:
    """Power-law noise type alpha (S_y ~ f^alpha) at averaging factor m, lag-1 ACF method.

    Parameters
    ----------
    rate : ndarray
        Evenly sampled rate data.
    m : int
        Averaging factor.
    dmax : int, optional
        Maximum number of differencings (2 for Allan variance).

    Returns
    -------
    int or None
        The noise type alpha in -2..2, or None when fewer than ``NOISE_ID_MIN_AVERAGES`` averages exist.

    Notes
    -----
    Riley & Greenhall, "Power law noise identification using the lag 1 autocorrelation" (2004):
    average over m, remove a linear trend, difference until rho = r1 / (1 + r1) < 0.25,
    alpha = -2 (round(rho) + d) with rho rounded to halves. Vectorised equivalent of
    ``allantools.autocorr_noise_id(data_type='freq')``.
    """
    n = len(rate) // m
    if n < NOISE_ID_MIN_AVERAGES:
        return None
    z = rate[:n * m].reshape(n, m).mean(axis=1)
    t = np.arange(n, dtype=float)
    z = z - np.polyval(np.polyfit(t, z, 1), t)
    d = 0
    while True:
        zc = z - z.mean()
        den = float(np.dot(zc, zc))
        r1 = float(np.dot(zc[:-1], zc[1:])) / den if den > 0 else 0.0
        rho = r1 / (1.0 + r1) if r1 > -1.0 else -1.0
        if rho < 0.25 or d >= dmax:
            return int(np.clip(-np.round(2.0 * rho) - 2 * d, -2, 2))
        z = np.diff(z)
        d += 1


def _edf(alpha: int, m: int, n_phase: int) -> float:
    """Greenhall EDF of the overlapping Allan variance (Stein's simple EDF where undefined)."""
    try:
        with contextlib.redirect_stdout(sys.stderr):
            return float(allantools.edf_greenhall(alpha=alpha, d=2, m=int(m), N=n_phase,
                                                  overlapping=True, modified=False))
    except (NotImplementedError, AssertionError, ZeroDivisionError, ValueError):
        return float(allantools.edf_simple(n_phase, int(m), alpha))


def local_slopes(taus_s: np.ndarray, adev: np.ndarray) -> np.ndarray:
    """Local log-log slope d ln(sigma) / d ln(tau): least squares over +-1 octave around each tau.

    Parameters
    ----------
    taus_s : ndarray
        Averaging times in s, increasing.
    adev : ndarray
        Deviation at each tau.

    Returns
    -------
    ndarray
        Slope at each tau (NaN where fewer than two positive points are in the window).
    """
    lt = np.log(taus_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        ls = np.where(adev > 0, np.log(np.where(adev > 0, adev, 1.0)), np.nan)
    out = np.full(len(taus_s), np.nan)
    for i in range(len(taus_s)):
        w = (np.abs(lt - lt[i]) <= math.log(2.0) * (1 + 1e-9)) & np.isfinite(ls)
        if w.sum() >= 2:
            x, y = lt[w] - lt[w].mean(), ls[w] - ls[w].mean()
            out[i] = float(np.dot(x, y) / np.dot(x, x))
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [start, stop) of the True runs of ``mask``."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


@dataclass
class FitTerm:
    """One straight line of given slope fitted on the log-log Allan curve.

    Parameters
    ----------
    slope : float
        Fixed log-log slope (-1, -1/2, +1/2).
    value : float or None
        The coefficient (N, K or Q) in the channel's unit system, None when not fitted.
    region_s : tuple of float or None
        (tau_first, tau_last) of the fitted region in s.
    reason : str or None
        Why the term is not reported (None when it is).
    """

    slope: float
    value: float | None = None
    region_s: tuple[float, float] | None = None
    reason: str | None = None


def _fit_line(taus, adev, edf, idx, slope, tau_read):
    """EDF-weighted fixed-slope fit ln(sigma) = c + slope ln(tau); returns sigma at tau_read."""
    w = edf[idx]
    c = np.sum(w * (np.log(adev[idx]) - slope * np.log(taus[idx]))) / np.sum(w)
    return float(math.exp(c + slope * math.log(tau_read)))


def _find_term(result: "AllanResult", usable: np.ndarray, slope: float, side: str, first: bool,
               tau_read: float, name: str) -> FitTerm:
    taus, sl = result.taus_s, result.slopes
    i_min = result._i_min
    side_mask = (np.arange(len(taus)) <= i_min) if side == "left" else (np.arange(len(taus)) >= i_min)
    ok = usable & side_mask & (np.abs(sl - slope) <= SLOPE_TOL)
    runs = [(a, b) for a, b in _runs(ok) if taus[b - 1] / taus[a] >= 2.0 * (1 - 1e-9)]
    if not runs:
        near = ", ".join(f"{t:.3g} s: {s:+.2f}" for t, s in zip(taus[usable & side_mask][:4], sl[usable & side_mask][:4]))
        where = "left of" if side == "left" else "right of"
        return FitTerm(slope, reason=(f"no {name} region: no run of local slope {slope:+g} +- {SLOPE_TOL:g} "
                                      f"spanning an octave {where} the Allan minimum (slopes {near}); "
                                      "the coefficient is not read outside a valid region"))
    a, b = runs[0] if first else runs[-1]
    idx = np.arange(a, b)
    val = _fit_line(taus, result.adev, result.edf, idx, slope, tau_read)
    return FitTerm(slope, val, (float(taus[a]), float(taus[b - 1])), None)


@dataclass
class AllanResult:
    """Overlapping Allan deviation with confidence intervals and the IEEE 952 noise terms.

    Parameters
    ----------
    taus_s : ndarray
        Averaging times in s.
    adev : ndarray
        OADEV at each tau, in ``unit`` (deg/s for ``rate_dps``).
    adev_lo, adev_hi : ndarray
        Lower and upper confidence limits at level ``ci``.
    n_clusters : ndarray of int
        Independent (non-overlapping) clusters N // m at each tau.
    n_pairs : ndarray of int
        Overlapping second differences averaged at each tau.
    alpha : ndarray of int
        Noise type used for the EDF at each tau (S_y ~ f^alpha).
    edf : ndarray
        Equivalent degrees of freedom at each tau.
    slopes : ndarray
        Local log-log slope at each tau.
    fs_Hz : float
        Sample rate.
    n_samples : int
        Length of the analysed series.
    unit : str
        Unit of the input and of ``adev``.
    ci : float
        Confidence level of ``adev_lo``/``adev_hi``.
    min_clusters : int
        Taus with fewer clusters are shown but not used for fits and the minimum.
    column : str, optional
        Name of the analysed channel.
    notes : list of str
        Human-readable remarks (data preparation, fits not made).
    white, random_walk, quantization : FitTerm
        The -1/2, +1/2 and -1 lines (filled by :func:`allan_deviation`).
    allan_minimum : float or None
        Minimum of ``adev`` over the usable taus, in ``unit``.
    tau_min_s : float or None
        Tau of that minimum.
    power_law : dict or None
        The power-law sum the ARW is read from: its coefficients ``C`` (unit^2 s^2), ``N2``
        (unit^2 s), ``B2`` (unit^2), ``K2`` (unit^2 / s) and the tau range fitted.
    """

    taus_s: np.ndarray
    adev: np.ndarray
    adev_lo: np.ndarray
    adev_hi: np.ndarray
    n_clusters: np.ndarray
    n_pairs: np.ndarray
    alpha: np.ndarray
    edf: np.ndarray
    slopes: np.ndarray
    fs_Hz: float
    n_samples: int
    unit: str = "deg/s"
    ci: float = CI_ONE_SIGMA
    min_clusters: int = 8
    column: str | None = None
    notes: list[str] = field(default_factory=list)
    white: FitTerm = field(default_factory=lambda: FitTerm(-0.5))
    random_walk: FitTerm = field(default_factory=lambda: FitTerm(0.5))
    quantization: FitTerm = field(default_factory=lambda: FitTerm(-1.0))
    allan_minimum: float | None = None
    tau_min_s: float | None = None
    power_law: dict | None = None
    _i_min: int = field(default=-1, init=False, repr=False)

    # --- generic terms, in the channel's unit -------------------------------------------
    @property
    def N(self) -> float | None:
        """White-noise coefficient N in unit*sqrt(s) (sigma of the -1/2 line at 1 s), or None."""
        return self.white.value

    @property
    def K(self) -> float | None:
        """Random-walk coefficient K in unit/sqrt(s) (the +1/2 line at 3 s), or None."""
        return self.random_walk.value

    @property
    def Q(self) -> float | None:
        """Quantisation coefficient Q in unit*s (the -1 line at sqrt(3) s), or None."""
        return self.quantization.value

    @property
    def is_deg_per_s(self) -> bool:
        """True when the input unit is deg/s, so the ``*_deg_*`` terms are defined."""
        return self.unit == "deg/s"

    def _deg(self, value: float | None, factor: float) -> float | None:
        return None if value is None or not self.is_deg_per_s else value * factor

    # --- gyro terms, deg-based -------------------------------------------------------------
    @property
    def arw_deg_per_sqrt_h(self) -> float | None:
        """Angle random walk N in deg/sqrt(h) (IEEE 952 -1/2 fit read at 1 s), or None."""
        return self._deg(self.N, ARW_TO_DEG_PER_SQRT_H)

    @property
    def bias_instability_deg_per_h(self) -> float | None:
        """Bias instability as the Allan minimum in deg/h (no 0.664 factor)."""
        return self._deg(self.allan_minimum, RATE_TO_DEG_PER_H)

    @property
    def bias_instability_ieee952_deg_per_h(self) -> float | None:
        """IEEE 952 flicker coefficient B = Allan minimum / 0.664, in deg/h."""
        v = self.bias_instability_deg_per_h
        return None if v is None else v / BI_IEEE952_FACTOR

    @property
    def rrw_deg_per_h_sqrt_h(self) -> float | None:
        """Rate random walk K in deg/h/sqrt(h) (IEEE 952 +1/2 fit read at 3 s), or None."""
        return self._deg(self.K, RRW_TO_DEG_PER_H_SQRT_H)

    @property
    def rrw(self) -> float | None:
        """Alias of :attr:`rrw_deg_per_h_sqrt_h` (the contract's ``rrw`` key)."""
        return self.rrw_deg_per_h_sqrt_h

    @property
    def rrw_deg_per_h_sqrt_s(self) -> float | None:
        """Rate random walk K in deg/h/sqrt(s) (= deg/h^2/sqrt(Hz)), or None."""
        return self._deg(self.K, RRW_TO_DEG_PER_H_SQRT_S)

    @property
    def quantization_deg(self) -> float | None:
        """Angle quantisation Q in deg (IEEE 952 -1 fit read at sqrt(3) s), or None."""
        return self._deg(self.Q, 1.0)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (NaN and missing values become None).

        Returns
        -------
        dict
            Curve (``taus_s``, ``adev``, ``adev_lo``, ``adev_hi``, ``n_clusters``, ``slopes``...),
            the gyro terms (``arw_deg_per_sqrt_h``, ``bias_instability_deg_per_h``,
            ``bias_instability_ieee952_deg_per_h``, ``tau_min_s``, ``rrw_deg_per_h_sqrt_h``,
            ``rrw``...), their regions and reasons, and the generic terms in ``unit``.
        """
        def num(v):
            return None if v is None or not np.isfinite(v) else float(v)

        def arr(a):
            return [num(v) for v in np.asarray(a, dtype=float)]

        def region(t):
            return None if t.region_s is None else [float(t.region_s[0]), float(t.region_s[1])]

        not_deg = None if self.is_deg_per_s else f"channel unit is {self.unit!r}, not deg/s; see the generic terms"
        return {
            "column": self.column,
            "unit": self.unit,
            "adev_unit": self.unit,
            "fs_Hz": float(self.fs_Hz),
            "n_samples": int(self.n_samples),
            "duration_s": float(self.n_samples / self.fs_Hz),
            "ci": float(self.ci),
            "ci_method": "chi-square with Greenhall EDF (allantools.edf_greenhall, overlapping) and lag-1 ACF noise ID",
            "min_clusters": int(self.min_clusters),
            "taus_s": arr(self.taus_s),
            "adev": arr(self.adev),
            "adev_lo": arr(self.adev_lo),
            "adev_hi": arr(self.adev_hi),
            "n_clusters": [int(v) for v in self.n_clusters],
            "n_pairs": [int(v) for v in self.n_pairs],
            "alpha": [int(v) for v in self.alpha],
            "edf": arr(self.edf),
            "slopes": arr(self.slopes),
            "arw_deg_per_sqrt_h": num(self.arw_deg_per_sqrt_h),
            "arw_definition": ARW_DEFINITION,
            "arw_power_law": None if self.power_law is None else {k: num(v) for k, v in self.power_law.items()},
            "arw_region_s": region(self.white),
            "arw_reason": self.white.reason or (not_deg if self.N is not None else None),
            "bias_instability_deg_per_h": num(self.bias_instability_deg_per_h),
            "bias_instability_definition": BI_DEFINITION,
            "bias_instability_ieee952_deg_per_h": num(self.bias_instability_ieee952_deg_per_h),
            "tau_min_s": num(self.tau_min_s),
            "rrw_deg_per_h_sqrt_h": num(self.rrw_deg_per_h_sqrt_h),
            "rrw": num(self.rrw),
            "rrw_deg_per_h_sqrt_s": num(self.rrw_deg_per_h_sqrt_s),
            "rrw_region_s": region(self.random_walk),
            "rrw_reason": self.random_walk.reason or (not_deg if self.K is not None else None),
            "quantization_deg": num(self.quantization_deg),
            "quantization_region_s": region(self.quantization),
            "quantization_reason": self.quantization.reason,
            "N_unit_sqrt_s": num(self.N),
            "allan_minimum_unit": num(self.allan_minimum),
            "K_unit_per_sqrt_s": num(self.K),
            "Q_unit_s": num(self.Q),
            "notes": list(self.notes),
        }

    def plot(self, path: str | Path, title: str | None = None) -> None:
        """Write a log-log PNG of the curve, its CI band and the fitted -1/2, 0, +1/2 lines.

        Parameters
        ----------
        path : path-like
            Destination PNG, written atomically.
        title : str, optional
            Figure title (default: the column name).
        """
        from .allan_plot import plot_allan
        plot_allan(self, path, title)


def allan_deviation(rate, fs_Hz: float, taus: str | np.ndarray = "octave", *, unit: str = "deg/s",
                    ci: float = CI_ONE_SIGMA, min_clusters: int = 8, stop_ratio: int = 4,
                    column: str | None = None) -> AllanResult:
    """Overlapping Allan deviation of evenly sampled rate data, with CIs and noise terms.

    Parameters
    ----------
    rate : array_like
        Evenly sampled, finite rate samples (deg/s for a gyro; any unit otherwise).
    fs_Hz : float
        Sample rate in Hz.
    taus : {"octave", "dense"} or array_like of float, optional
        Octave taus (default), about 10 log-spaced taus per decade, or explicit taus in s.
    unit : str, optional
        Unit of ``rate``; the ``*_deg_*`` terms are computed only for ``"deg/s"``.
    ci : float, optional
        Confidence level of the interval (default one sigma, 0.683).
    min_clusters : int, optional
        Minimum number of independent clusters N // m for a tau to enter fits and the minimum.
    stop_ratio : int, optional
        Automatic tau lists stop at m <= (N + 1) / stop_ratio (Stable32: 4).
    column : str, optional
        Channel name, carried into the result.

    Returns
    -------
    AllanResult
        Curve, confidence limits, local slopes and the IEEE 952 terms.

    Raises
    ------
    InputError
        Non-finite samples, a non-positive sample rate or too few samples.
    """
    y = np.asarray(rate, dtype=float).ravel()
    if not (np.isfinite(fs_Hz) and fs_Hz > 0):
        raise InputError(f"sample rate must be positive, got {fs_Hz!r} Hz")
    if not np.isfinite(y).all():
        k = int(np.flatnonzero(~np.isfinite(y))[0])
        raise InputError(f"sample {k} is not finite; prepare the series first (series_from_record)")
    n = len(y)
    m = averaging_factors(n, taus, fs_Hz, stop_ratio)
    with contextlib.redirect_stdout(sys.stderr):  # allantools prints its own warnings
        t_out, dev, _, ns = allantools.oadev(y, rate=fs_Hz, data_type="freq", taus=m / fs_Hz)
    m = np.round(np.asarray(t_out) * fs_Hz).astype(np.int64)
    taus_s = m / fs_Hz
    dev = np.asarray(dev, dtype=float)
    n_phase = n + 1

    slopes = local_slopes(taus_s, dev)
    alpha = np.zeros(len(m), dtype=int)
    for i, mi in enumerate(m):
        a = noise_alpha(y, int(mi))
        if a is None:
            a = int(np.clip(np.round(-2.0 * slopes[i] - 1.0), -2, 1)) if np.isfinite(slopes[i]) else 0
        alpha[i] = a
    edf = np.array([_edf(int(a), int(mi), n_phase) for a, mi in zip(alpha, m)])
    lo = np.empty(len(m))
    hi = np.empty(len(m))
    for i in range(len(m)):
        if dev[i] > 0 and np.isfinite(edf[i]) and edf[i] > 0:
            lo[i], hi[i] = allantools.confidence_interval(dev[i], edf[i], ci)
        else:
            lo[i] = hi[i] = dev[i]

    res = AllanResult(taus_s=taus_s, adev=dev, adev_lo=lo, adev_hi=hi, n_clusters=n // m,
                      n_pairs=np.asarray(ns).astype(np.int64), alpha=alpha, edf=edf,
                      slopes=slopes, fs_Hz=float(fs_Hz), n_samples=n, unit=unit,
                      ci=ci, min_clusters=min_clusters, column=column)
    _read_terms(res)
    return res


def _read_terms(res: AllanResult) -> None:
    """Fill the minimum and the fitted terms of ``res`` (IEEE 952 rules, module docstring)."""
    usable = (res.n_clusters >= res.min_clusters) & (res.adev > 0) & np.isfinite(res.slopes)
    if not usable.any():
        usable = res.adev > 0
        res.notes.append(f"no tau has {res.min_clusters} clusters; the minimum uses all taus and no term is fitted")
        if not usable.any():
            res.notes.append("the deviation is zero at every tau (constant input)")
            for t in (res.white, res.random_walk, res.quantization):
                t.reason = "the deviation is zero at every tau"
            return
        fit_ok = np.zeros_like(usable)
    else:
        fit_ok = usable
    idx = np.flatnonzero(usable)
    i_min = int(idx[np.argmin(res.adev[idx])])
    res._i_min = i_min
    res.allan_minimum = float(res.adev[i_min])
    res.tau_min_s = float(res.taus_s[i_min])
    if i_min == idx[-1]:
        res.notes.append(f"the curve still falls at the longest usable tau ({res.taus_s[i_min]:.4g} s, "
                         f">= {res.min_clusters} clusters): the Allan minimum is an upper bound, not a flat floor")
    elif i_min == idx[0]:
        res.notes.append("the curve rises from the shortest tau: the Allan minimum is at the first tau")
    res.white = _find_term(res, fit_ok, -0.5, "left", True, 1.0, "-1/2 (white noise)")
    if res.white.value is not None:
        _fit_white(res, fit_ok)
    res.random_walk = _find_term(res, fit_ok, 0.5, "right", False, 3.0, "+1/2 (random walk)")
    res.quantization = _find_term(res, fit_ok, -1.0, "left", True, math.sqrt(3.0), "-1 (quantisation)")
    for name, t in (("ARW", res.white), ("RRW", res.random_walk)):
        if t.reason:
            res.notes.append(f"{name} not reported: {t.reason}")


def _power_law_fit(taus, adev, edf, idx, terms):
    """EDF-weighted least squares of ``sigma^2`` by the ``terms`` among N^2/tau, B^2, C/tau^2, K^2 tau/3.

    Relative residuals of the variance, each weighted by its EDF (var(sigma^2)/sigma^4 = 2/EDF);
    N^2, B^2, K^2 are kept non-negative, C (a filter's deficit or quantisation) takes either sign.
    Returns the coefficients (C, N2, B2, K2) and ln(model sigma / sigma) at ``idx``.
    """
    t, s2, w = taus[idx], adev[idx] ** 2, np.sqrt(edf[idx])
    basis = {"N2": 1.0 / t, "B2": np.ones_like(t), "C": 1.0 / t ** 2, "K2": t / 3.0}
    F = np.column_stack([basis[k] for k in terms])
    lo = [-np.inf if k == "C" else 0.0 for k in terms]
    sol = lsq_linear(F / s2[:, None] * w[:, None], w, bounds=(lo, [np.inf] * len(terms)))
    coef = dict.fromkeys(("C", "N2", "B2", "K2"), 0.0)
    coef.update(zip(terms, (float(v) for v in sol.x)))
    model = F @ sol.x
    with np.errstate(divide="ignore", invalid="ignore"):
        resid = 0.5 * np.log(np.where(model > 0, model, np.nan) / s2)
    return coef, resid


#: The power-law sums tried in turn at each start tau: the simplest that fits is kept.
_POWER_LAW_MODELS = (("N2", "B2"), ("N2", "B2", "C"), ("N2", "B2", "C", "K2"))


def _fit_white(res: AllanResult, usable: np.ndarray) -> None:
    """Replace the -1/2 line of ``res.white`` by the white term of the power-law sum (module docstring).

    From the start of the -1/2 run on, each start tau is tried with white + flicker, then with the
    1/tau^2 term, then with rate random walk added; the first (start, sum) that fits every point up
    to the Allan minimum within :data:`FIT_SIGMAS` confidence half-widths gives N.
    """
    a = int(np.searchsorted(res.taus_s, res.white.region_s[0]))
    i_min = res._i_min
    ci = 0.5 * np.log(res.adev_hi / np.where(res.adev_lo > 0, res.adev_lo, res.adev_hi))
    best = None
    for i0 in range(a, i_min + 1):
        idx = np.arange(i0, i_min + 1)
        idx = idx[usable[idx]]
        if len(idx) < 3 or res.taus_s[idx[-1]] / res.taus_s[idx[0]] < 2.0 * (1 - 1e-9):
            break
        for terms in _POWER_LAW_MODELS:
            if len(idx) < len(terms) + 2:
                break
            coef, resid = _power_law_fit(res.taus_s, res.adev, res.edf, idx, terms)
            if coef["N2"] <= 0:
                continue
            near = res.taus_s[idx] <= SHAPED_SPAN * res.taus_s[idx[0]]  # where a filter would show
            misfit = float(np.nanmax(np.abs(resid[near]) / np.maximum(ci[idx][near], 1e-12)))
            if best is None or misfit < best[0]:
                best = (misfit, idx, coef)
            if misfit <= FIT_SIGMAS:
                break
        if best is not None and best[0] <= FIT_SIGMAS:
            break
    if best is None:
        res.notes.append("ARW: the power-law sum could not be fitted; N is the -1/2 line's")
        return
    misfit, idx, coef = best
    if misfit > FIT_SIGMAS:
        res.notes.append(f"ARW: no start tau lets the power-law sum fit within {FIT_SIGMAS:g} sigma "
                         f"(best {misfit:.1f} sigma, from {res.taus_s[idx[0]]:.4g} s)")
    res.white = FitTerm(-0.5, float(math.sqrt(coef["N2"])), (float(res.taus_s[idx[0]]), float(res.taus_s[idx[-1]])))
    res.power_law = dict(coef, tau_first_s=float(res.taus_s[idx[0]]), tau_last_s=float(res.taus_s[idx[-1]]))
