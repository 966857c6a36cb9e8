"""The selected temperature model: a polynomial in T, with or without a dT/dt term.

The drift is modelled on 1 s bin means (bins never straddle a gap) as

    drift = c0 + c1 dT + ... + c_p dT^p  [+ c_d dT/dt]

with dT = T - T_ref and dT/dt a local least-squares slope over a smoothing span, taken
inside each stretch between gaps. Which order p (0-3), whether dT/dt enters and over what
span are chosen by forward-chained validation on the training record (:mod:`.selection`);
a dT/dt span is offered only when at least half of the record lies in stretches that long
(on a record of 5 s bursts no derivative over 60 s exists, so none is offered).

Beyond the training temperature range the polynomial is continued from the range's edge,
along its tangent or as a constant, as the validation's forecasts beyond their fitted range
support (no curvature is ever extrapolated), and :meth:`TemperatureModel.extrapolation` says
by how much the applied record left the range and which terms that touched.
"""

from __future__ import annotations

import numpy as np

from .segments import Bins, describe, make_bins, slope_within
from .selection import Candidate, Selection, chained_folds, select, time_blocks

#: Polynomial orders offered by default.
ORDERS = (0, 1, 2, 3)
#: dT/dt smoothing spans offered by default, in s (None: no dT/dt term).
DTDT_SMOOTHING_S = (None, 60.0, 300.0, 900.0)
#: Span of the dT/dt slope on a temperature that is already a smooth trend, in s.
TREND_SLOPE_S = 10.0
UNITS = {"dT": "K", "dTdt": "K/min"}
#: How the model continues beyond its training range, in words.
CONTINUATION_TEXT = {"tangent": "continued along the tangent at the range's edge (no curvature extrapolated)",
                     "slope": "continued from its value at the range's edge along the slope of a line fitted on "
                              "the whole range, and held there along a variable whose slope is not significant "
                              "(no curvature extrapolated)",
                     "constant": "held at its value at the range's edge (the validation did not support a slope "
                                 "beyond the range)"}


class TemperatureModel:
    """Polynomial in T (+ dT/dt) chosen by forward-chained validation, fitted on bins.

    Parameters
    ----------
    orders : sequence of int
        Polynomial orders to choose from.
    dtdt_smoothing_s : sequence of float or None
        dT/dt smoothing spans to choose from; None stands for "no dT/dt term".
    rule : {"best", "one-se"}
        Selection rule (:func:`.selection.select`).
    n_folds : int
        Forward-chained folds.
    min_train_fraction : float
        Fraction of the record the first fold is fitted on.
    bin_s : float
        Bin width in s.
    presmoothed : bool
        The temperature given is already a smooth trend: dT/dt is its local slope over
        :data:`TREND_SLOPE_S` and the smoothing span is not a choice.
    continuation : {"auto", "tangent", "constant"}
        Beyond the training range: as the validation supports, or fixed.
    """

    def __init__(self, orders=ORDERS, dtdt_smoothing_s=DTDT_SMOOTHING_S, rule="best", n_folds=4,
                 min_train_fraction=0.5, bin_s=1.0, presmoothed=False, continuation="auto"):
        self.continuation = continuation
        self.orders = tuple(orders)
        self.dtdt_smoothing_s = tuple(dtdt_smoothing_s)
        self.rule, self.n_folds, self.min_train_fraction = rule, n_folds, min_train_fraction
        self.bin_s, self.presmoothed = bin_s, presmoothed

    # -- features ------------------------------------------------------------------------------
    def _spans(self) -> list:
        if self.presmoothed:
            return [None] + ([TREND_SLOPE_S] if any(s is not None for s in self.dtdt_smoothing_s) else [])
        return list(dict.fromkeys(self.dtdt_smoothing_s))

    def offered_spans(self, bins: Bins) -> tuple[list, str | None]:
        """The dT/dt spans a record affords: at least half of it in stretches that long.

        Parameters
        ----------
        bins : Bins
            The record's bins.

        Returns
        -------
        (list, str or None)
            Spans offered (None, "no dT/dt", always) and a note on those refused.
        """
        seg_len = np.array([bins.t_s[s][-1] - bins.t_s[s][0] + bins.width_s for s in bins.segments()])
        seg_w = np.array([bins.counts[s].sum() for s in bins.segments()])
        spans, refused = [], []
        for span in self._spans():
            ok = span is None or self.presmoothed or seg_w[seg_len >= span].sum() >= 0.5 * seg_w.sum()
            (spans if ok else refused).append(span)
        note = None
        if refused:
            note = (f"dT/dt over {', '.join(f'{s:g}' for s in refused)} s not offered: less than half of the "
                    f"record lies in stretches that long (the longest is {seg_len.max():.3g} s; derivatives "
                    "never straddle a gap)")
        return spans, note

    def base(self, bins: Bins, Tb: np.ndarray, span) -> np.ndarray:
        """Base variables per bin: ``[dT]`` or ``[dT, dT/dt in K/min]``.

        Parameters
        ----------
        bins : Bins
        Tb : ndarray
            Temperature bin means.
        span : float or None
            dT/dt smoothing span (None: no dT/dt column).

        Returns
        -------
        ndarray, shape (n_bins, 1 or 2)
        """
        dT = Tb - self.T_ref_C_
        if span is None:
            return dT[:, None]
        return np.column_stack([dT, slope_within(bins, Tb, span) * 60.0])

    def candidates(self, spans: list) -> list[Candidate]:
        """Every (order, dT/dt span) structure offered.

        Parameters
        ----------
        spans : list
            dT/dt spans offered (None included for "no dT/dt").

        Returns
        -------
        list of Candidate
        """
        out = []
        for span in spans:
            for p in self.orders:
                if span is None:
                    out.append(Candidate(f"order {p}", None, ["dT"], [(k,) for k in range(1, p + 1)],
                                         {"order": p, "dTdt_smoothing_s": None}))
                else:
                    label = "trend slope" if self.presmoothed else f"{span:g} s"
                    out.append(Candidate(f"order {p} + dT/dt ({label})", span, ["dT", "dTdt"],
                                         [(k, 0) for k in range(1, p + 1)] + [(0, 1)],
                                         {"order": p, "dTdt_smoothing_s": span}))
        return out

    # -- fit / predict -------------------------------------------------------------------------
    def fit(self, t_s: np.ndarray, T_C: np.ndarray, target: np.ndarray) -> "TemperatureModel":
        """Choose the structure and fit it on the whole training record.

        Parameters
        ----------
        t_s : ndarray
            Times (gaps allowed).
        T_C : ndarray
            Temperature (or its trend with ``presmoothed``).
        target : ndarray
            The drift to model, one value per sample (deg/s).

        Returns
        -------
        TemperatureModel
            ``self`` with ``selection_`` (:class:`.selection.Selection`), ``model_`` (the fitted
            :class:`.selection.MonomialModel`), ``span_`` (dT/dt span or None), ``T_ref_C_``
            and ``sampling_`` (:func:`.segments.describe`).
        """
        bins = make_bins(t_s, self.bin_s)
        self.sampling_ = describe(t_s)
        Tb, yb = bins.mean(T_C), bins.mean(target)
        self.T_ref_C_ = float(np.average(Tb, weights=bins.counts))
        spans, note = self.offered_spans(bins)
        notes = [note] if note else []
        base = {s: self.base(bins, Tb, s) for s in spans}
        folds = chained_folds(bins, self.n_folds, self.min_train_fraction, by_segment=self.sampling_["bursty"])
        sel = select(self.candidates(spans), base, yb, bins.counts, folds, bins.t_s, self.rule,
                     range_vars=(Tb - self.T_ref_C_)[:, None], continuation=self.continuation,
                     blocks=time_blocks(bins, 8, self.sampling_["bursty"]))
        sel.notes = notes + sel.notes
        self.selection_: Selection = sel
        self.span_ = sel.chosen.key
        self.model_ = sel.chosen.model().fit(base[self.span_], yb, bins.counts)
        self.T_range_C_ = (float(Tb.min()), float(Tb.max()))
        return self

    def _base_of(self, t_s, T_C) -> tuple[Bins, np.ndarray]:
        bins = make_bins(t_s, self.bin_s)
        return bins, self.base(bins, bins.mean(T_C), self.span_)

    def predict(self, t_s: np.ndarray, T_C: np.ndarray) -> np.ndarray:
        """The modelled drift at every sample (deg/s); tangent continuation beyond the training range.

        Parameters
        ----------
        t_s, T_C : ndarray
            Times and temperature of the record to compensate.

        Returns
        -------
        ndarray
        """
        bins, X = self._base_of(t_s, T_C)
        return bins.to_samples(np.asarray(t_s, float), self.model_.predict(X))

    def extrapolation(self, t_s: np.ndarray, T_C: np.ndarray) -> dict:
        """How far the record leaves the training range (temperature in degC, dT/dt in K/min).

        Parameters
        ----------
        t_s, T_C : ndarray

        Returns
        -------
        dict
            :meth:`.selection.MonomialModel.extrapolation` with the temperature reported as
            ``temperature_C`` (absolute degC) and a one-line ``summary``.
        """
        bins, X = self._base_of(t_s, T_C)
        ex = self.model_.extrapolation(X, bins.counts, UNITS)
        v = ex["variables"]
        if "dT" in v:
            d = v.pop("dT")
            d["fit_range"] = [r + self.T_ref_C_ for r in d["fit_range"]]
            d["applied_range"] = [r + self.T_ref_C_ for r in d["applied_range"]]
            d["unit"] = "degC"
            v["temperature_C"] = d
        ex["summary"] = summarise_extrapolation(ex)
        return ex

    def report(self) -> dict:
        """What was chosen, the validation score of every option, and the fitted coefficients.

        Returns
        -------
        dict
        """
        return {"selection": self.selection_.report(), "terms": self.model_.terms,
                "coef_dps": self.model_.coefficients(), "T_ref_C": self.T_ref_C_,
                "training_temperature_range_C": list(self.T_range_C_), "sampling": self.sampling_,
                "beyond_training_range": {"continuation": self.model_.continuation, "held": list(self.model_.held),
                                          "how": CONTINUATION_TEXT[self.model_.continuation]}}


def summarise_extrapolation(ex: dict) -> str:
    """One line on what an extrapolation report holds.

    Parameters
    ----------
    ex : dict
        From :meth:`.selection.MonomialModel.extrapolation`.

    Returns
    -------
    str
    """
    if not ex.get("any"):
        return "the record stays inside the training range"
    parts = []
    for name, d in ex["variables"].items():
        side = []
        if d["below"] > 0:
            side.append(f"{d['below']:.3g} {d['unit']} below")
        if d["above"] > 0:
            side.append(f"{d['above']:.3g} {d['unit']} above")
        if side:
            parts.append(f"{name} goes {' and '.join(side)} the training range "
                         f"({100 * d['fraction_outside']:.0f} % of the record)")
    s = "; ".join(parts) + f"; terms extrapolated: {', '.join(ex['terms_extrapolated'])}"
    out = [n for n, d in ex["variables"].items() if d["below"] > 0 or d["above"] > 0]
    held = [n for n in out if ex.get("continuation") == "constant" or n in ex.get("held", ())
            or (n == "temperature_C" and "dT" in ex.get("held", ()))]
    moving = [n for n in out if n not in held]
    how = []
    if held:
        how.append(f"held at its value at the range's edge along {', '.join(held)}")
    if moving:
        how.append({"slope": "continued along the slope of a line fitted on the whole training range",
                    "tangent": "continued along the tangent at the range's edge"}[ex.get("continuation", "tangent")]
                   + f" along {', '.join(moving)}")
    s += " (" + "; ".join(how) + ")"
    return s
