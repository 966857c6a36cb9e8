"""The temperature-model compensators ``poly-baseline``, ``line`` and ``bias``, and the record checks every method shares.

``poly-baseline`` models the rate error (``rate_dps - rate_true_dps``, the truth taken as 0
when absent: a static record) by the selected temperature model of :mod:`.thermal_model`: a
polynomial of order 0-3 in T, with or without a dT/dt term, chosen by forward-chained
validation on the training record, fitted on 1 s bin means, continued along its tangent
beyond the training temperature range. ``line`` (a straight line in T) and ``bias`` (a
constant) are the fixed baselines every other method is compared with. All three handle gaps
and records of bursts: bins, derivatives and validation folds stay inside the stretches
between gaps.
"""

from __future__ import annotations

import numpy as np
from sklearn.utils.validation import check_is_fitted

from ..errors import InputError
from ..record import Record
from .base import Compensator, register
from .segments import describe
from .thermal_model import DTDT_SMOOTHING_S, ORDERS, TemperatureModel


#: Channels every compensator reads.
NEEDED = ("time_s", "temperature_C", "rate_dps")


def check_record(record: Record, need_uniform: bool, min_samples: int = 16, method: str = "",
                 allow_missing: bool = False) -> None:
    """Refuse a record a compensator cannot use (raises :class:`InputError`).

    Parameters
    ----------
    record : Record
        The record.
    need_uniform : bool
        Whether the method needs even time steps (no gaps).
    min_samples : int
        Fewest (complete) rows accepted.
    method : str
        Method name for the message.
    allow_missing : bool
        Accept rows with a missing ``temperature_C`` or ``rate_dps`` (a method that treats
        them as gaps, see :func:`complete_rows`).

    Raises
    ------
    InputError
        A missing column, missing samples (unless ``allow_missing``), too few rows, or gaps
        when ``need_uniform``.
    """
    where = record.path or "record"
    ok = np.ones(len(record), dtype=bool)
    for col in NEEDED:
        if col not in record:
            raise InputError(f"column {col!r} is required by compensation method {method!r}", where)
        bad = np.flatnonzero(~np.isfinite(record[col]))
        if bad.size and (not allow_missing or col == "time_s"):
            raise InputError(f"{col} has {bad.size} missing/NaN samples (first at data row {bad[0] + 1}); "
                             f"compensation method {method!r} needs complete channels (poly-baseline, line, "
                             "bias and physics treat rows with a missing rate or temperature as gaps)", where)
        ok &= np.isfinite(record[col])
    if ok.sum() < min_samples:
        raise InputError(f"record has {int(ok.sum())} complete rows; method {method!r} needs at least "
                         f"{min_samples}", where)
    if need_uniform:
        dt = np.diff(record.time_s)
        med = np.median(dt)
        off = np.flatnonzero(np.abs(dt - med) > 1e-3 * med)
        if off.size:
            s = describe(record.time_s)
            what = (f"the record is made of {s['segments']} bursts of about {s['median_segment_s']:.3g} s every "
                    f"{s['median_segment_s'] + s['median_gap_s']:.3g} s" if s["bursty"] else
                    f"time_s has uneven steps (gap after t={record.time_s[off[0]]:g} s: step {dt[off[0]]:g} s "
                    f"vs nominal {med:g} s)")
            raise InputError(f"{what}; method {method!r} needs even, continuous sampling (use poly-baseline, "
                             "line, bias or physics, which handle gaps and bursts)", where)


def complete_rows(record: Record) -> tuple[Record, np.ndarray, str | None]:
    """The rows whose ``time_s``, ``temperature_C`` and ``rate_dps`` are all known.

    The rows left out become gaps for the methods that handle gaps (bins and derivatives do not
    straddle them); their compensated output is missing.

    Parameters
    ----------
    record : Record

    Returns
    -------
    (Record, ndarray of bool, str or None)
        The complete rows, the mask of them, and a note when rows were left out.
    """
    keep = np.ones(len(record), dtype=bool)
    for col in NEEDED:
        keep &= np.isfinite(record[col])
    if keep.all():
        return record, keep, None
    first = int(np.flatnonzero(~keep)[0]) + 1
    return (record.slice(keep), keep,
            f"{int((~keep).sum())} rows with a missing rate or temperature (first at data row {first}) treated as "
            "gaps; their compensated rate is missing")


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


class _TemperatureCompensator(Compensator):
    """Shared fit/transform of the compensators built on :class:`.thermal_model.TemperatureModel`."""

    handles_gaps = True

    def _model(self) -> TemperatureModel:
        return TemperatureModel(self.orders, self.dtdt_smoothing_s, self.rule, self.n_folds,
                                self.min_train_fraction, continuation=self.continuation)

    def fit(self, record: Record) -> "_TemperatureCompensator":
        """Choose and fit the temperature model on a training record.

        Parameters
        ----------
        record : Record
            Training data (``rate_true_dps`` used where known; a static run otherwise).

        Returns
        -------
        self
            With ``model_`` (the fitted :class:`.thermal_model.TemperatureModel`), ``coef_``
            (``{term: deg/s per unit}``), ``T_ref_C_`` and ``diagnostics_`` (the selection with
            every option's validation score).
        """
        check_record(record, need_uniform=False, method=self.method_name, allow_missing=True)
        rec, _, note = complete_rows(record)
        self.model_ = self._model().fit(rec.time_s, rec["temperature_C"], rate_error(rec))
        self.T_ref_C_ = self.model_.T_ref_C_
        self.coef_ = self.model_.model_.coefficients()
        self.diagnostics_ = {"method": self.method_name, **self.model_.report(), "filter_time_constant_s": 0.0,
                             "notes": self.model_.selection_.notes + ([note] if note else [])}
        return self

    def compensate_rate_dps(self, record: Record) -> np.ndarray:
        """Rate with the fitted temperature model subtracted, in deg/s.

        Parameters
        ----------
        record : Record
            Record to compensate.

        Returns
        -------
        ndarray
            ``transform_diagnostics_["extrapolation"]`` says whether and how far the record left
            the training range.
        """
        check_is_fitted(self, "model_")
        check_record(record, need_uniform=False, min_samples=1, method=self.method_name, allow_missing=True)
        rec, keep, note = complete_rows(record)
        t, T = rec.time_s, rec["temperature_C"]
        self.transform_diagnostics_ = {"extrapolation": self.model_.extrapolation(t, T),
                                       "sampling": describe(t), "filter_time_constant_s": 0.0,
                                       "notes": [note] if note else []}
        out = np.full(len(record), np.nan)
        out[keep] = rec["rate_dps"] - self.model_.predict(t, T)
        return out


@register("poly-baseline")
class PolyBaseline(_TemperatureCompensator):
    """Polynomial in T (order 0-3) with or without dT/dt, chosen by forward-chained validation.

    Parameters
    ----------
    orders : tuple of int, optional
        Polynomial orders to choose from.
    dtdt_smoothing_s : tuple of float or None, optional
        dT/dt smoothing spans to choose from, in s; None stands for "no dT/dt term".
    rule : {"best", "one-se"}, optional
        The simplest structure within one standard error of the best validation score, or the
        best score.
    n_folds : int, optional
        Forward-chained validation folds.
    min_train_fraction : float, optional
        Fraction of the training record the first fold of each direction is fitted on.
    continuation : {"auto", "tangent", "constant"}, optional
        Beyond the training temperature range: held constant or continued along the tangent
        as the validation's forecasts beyond their fitted range support (``"auto"``), or fixed.
    """

    def __init__(self, orders=ORDERS, dtdt_smoothing_s=DTDT_SMOOTHING_S, rule="best", n_folds=4,
                 min_train_fraction=0.5, continuation="auto"):
        self.orders, self.dtdt_smoothing_s, self.rule = orders, dtdt_smoothing_s, rule
        self.n_folds, self.min_train_fraction, self.continuation = n_folds, min_train_fraction, continuation


@register("line")
class LineInT(_TemperatureCompensator):
    """A straight line in T (bias and one temperature coefficient): the baseline to beat."""

    orders, dtdt_smoothing_s, rule, n_folds, min_train_fraction, continuation = (1,), (None,), "best", 4, 0.5, "tangent"


@register("bias")
class BiasOnly(_TemperatureCompensator):
    """A constant bias from the training record (a plain bias calibration)."""

    orders, dtdt_smoothing_s, rule, n_folds, min_train_fraction, continuation = (0,), (None,), "best", 4, 0.5, "tangent"
