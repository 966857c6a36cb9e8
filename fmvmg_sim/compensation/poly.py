"""The ``poly-baseline`` compensator and the thermal regressors every method shares.

Model of the rate error (rate_dps - rate_true_dps, the truth taken as 0 when absent):
b + a1 dT + a2 dT^2 + c dT/dt, by ordinary least squares on training data, evaluated on
1 s bin means (compensation.md: regressors at 1 Hz). Temperature is smoothed over 60 s
before dT/dt is taken. Works on uneven time steps (gaps): bins and derivatives use the
actual times.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

from ..errors import InputError
from ..record import Record
from .base import Compensator, register


def check_record(record: Record, need_uniform: bool, min_samples: int = 16, method: str = "") -> None:
    """Refuse a record a compensator cannot use (raises :class:`InputError`).

    Parameters
    ----------
    record : Record
        The record.
    need_uniform : bool
        Whether the method needs even time steps (no gaps).
    min_samples : int
        Fewest rows accepted.
    method : str
        Method name for the message.

    Raises
    ------
    InputError
        Missing or non-finite ``temperature_C``/``rate_dps``, too few rows, or gaps when
        ``need_uniform``.
    """
    where = record.path or "record"
    for col in ("time_s", "temperature_C", "rate_dps"):
        if col not in record:
            raise InputError(f"column {col!r} is required by compensation method {method!r}", where)
        bad = np.flatnonzero(~np.isfinite(record[col]))
        if bad.size:
            raise InputError(f"{col} has {bad.size} missing/NaN samples (first at data row {bad[0] + 1}); "
                             f"compensation method {method!r} needs complete channels", where)
    if len(record) < min_samples:
        raise InputError(f"record has {len(record)} rows; method {method!r} needs at least {min_samples}", where)
    if need_uniform:
        dt = np.diff(record.time_s)
        med = np.median(dt)
        off = np.flatnonzero(np.abs(dt - med) > 1e-3 * med)
        if off.size:
            raise InputError(f"time_s has uneven steps (gap after t={record.time_s[off[0]]:g} s: step "
                             f"{dt[off[0]]:g} s vs nominal {med:g} s); method {method!r} needs even "
                             "sampling (use poly-baseline, or resample the record)", where)


def rate_error(record: Record) -> np.ndarray:
    """Rate output minus the known true rate (0 where unknown), in deg/s.

    Parameters
    ----------
    record : Record
        A record.

    Returns
    -------
    ndarray
    """
    y = record["rate_dps"]
    if record.has("rate_true_dps"):
        return y - np.nan_to_num(record["rate_true_dps"])
    return y.copy()


def bin_means(t_s: np.ndarray, x: np.ndarray, width_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Means of ``x`` (and of time) over non-empty bins of ``width_s`` seconds.

    Parameters
    ----------
    t_s : ndarray
        Increasing times.
    x : ndarray
        Values.
    width_s : float
        Bin width.

    Returns
    -------
    t_bin, x_bin : ndarray
    """
    idx = np.floor((t_s - t_s[0]) / width_s).astype(np.int64)
    _, start, counts = np.unique(idx, return_index=True, return_counts=True)
    return np.add.reduceat(t_s, start) / counts, np.add.reduceat(x, start) / counts


def thermal_features(t_s: np.ndarray, T_C: np.ndarray, T_ref_C: float, smooth_s: float = 60.0,
                     presmoothed: bool = False) -> np.ndarray:
    """Regressors [dT, dT^2, dT/dt in degC/min] on the time base ``t_s``.

    Parameters
    ----------
    t_s : ndarray
        Times (gaps allowed).
    T_C : ndarray
        Temperature readings, or a trend when ``presmoothed``.
    T_ref_C : float
        Reference temperature of dT.
    smooth_s : float
        Moving-average span applied to 1 s bin means before differentiating.
    presmoothed : bool
        ``T_C`` is already a smooth trend (skip the moving average).

    Returns
    -------
    ndarray, shape (len(t_s), 3)
    """
    tb, Tb = bin_means(t_s, T_C, 1.0)
    if not presmoothed and len(Tb) > 2:
        Tb = uniform_filter1d(Tb, max(1, min(int(smooth_s), len(Tb))), mode="nearest")
    dTdt = np.gradient(Tb, tb) * 60.0 if len(Tb) > 1 else np.zeros_like(Tb)
    if not presmoothed and len(Tb) > 2:
        dTdt = uniform_filter1d(dTdt, max(1, min(int(smooth_s), len(Tb))), mode="nearest")
    dT = np.interp(t_s, tb, Tb) - T_ref_C
    return np.column_stack([dT, dT * dT, np.interp(t_s, tb, dTdt)])


def fit_ols(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of ``y`` on ``[1, X]``.

    Parameters
    ----------
    X : ndarray, shape (n, p)
        Regressors.
    y : ndarray, shape (n,)
        Target.

    Returns
    -------
    ndarray, shape (p + 1,)
        Intercept first.
    """
    A = np.column_stack([np.ones(len(X)), X])
    return np.linalg.lstsq(A, y, rcond=None)[0]


@register("poly-baseline")
class PolyBaseline(Compensator):
    """Least squares on [1, dT, dT^2, dT/dt] fitted on training data; handles gaps.

    Parameters
    ----------
    smooth_s : float
        Temperature smoothing span before the derivative, in s.
    """

    handles_gaps = True

    def __init__(self, smooth_s: float = 60.0):
        self.smooth_s = smooth_s

    def fit(self, record: Record) -> "PolyBaseline":
        """Fit the coefficients on a training record.

        Parameters
        ----------
        record : Record
            Training data.

        Returns
        -------
        PolyBaseline
            ``self`` with ``T_ref_C_`` and ``coef_`` (intercept, dT, dT^2, dT/dt; deg/s units).
        """
        check_record(record, need_uniform=False, method=self.method_name)
        t = record.time_s
        self.T_ref_C_ = float(np.mean(record["temperature_C"]))
        X = thermal_features(t, record["temperature_C"], self.T_ref_C_, self.smooth_s)
        Xb = np.column_stack([bin_means(t, X[:, k])[1] for k in range(X.shape[1])])
        self.coef_ = fit_ols(Xb, bin_means(t, rate_error(record))[1])
        self.diagnostics_ = {"coef_dps": self.coef_.tolist(), "T_ref_C": self.T_ref_C_, "bins_1s": len(Xb)}
        return self

    def transform(self, record: Record) -> np.ndarray:
        """Rate with the fitted thermal error model subtracted, in deg/s.

        Parameters
        ----------
        record : Record
            Record to compensate.

        Returns
        -------
        ndarray
        """
        check_record(record, need_uniform=False, method=self.method_name)
        X = thermal_features(record.time_s, record["temperature_C"], self.T_ref_C_, self.smooth_s)
        return record["rate_dps"] - (self.coef_[0] + X @ self.coef_[1:])
