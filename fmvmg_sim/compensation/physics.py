"""The ``physics`` compensator: a drift model on the gyro's own auxiliary channels.

Where the drift comes from
--------------------------
In an open-loop vibratory gyro the zero-rate output is mostly quadrature leaking into the
rate channel through a phase error between the sense signal and the demodulation
reference: rate_err ~ Q * sin(phi(T_die)) + (damping asymmetry ~ 1/Q_factor) + small
electronic offsets. The record carries the three quantities this needs, measured by the
gyro itself rather than by a thermometer glued to the case:

* ``quadrature_V``: the quadrature amplitude Q that leaks;
* ``drive_frequency_Hz``: the drive resonance falls about 0.92 Hz/K, so it is the die's own
  thermometer and follows the die through any thermal lag between case and die;
* ``agc_effort_V``: the drive-amplitude control effort, proportional to the drive damping
  (1/Q factor), so it tracks the damping-asymmetry term.

Regressors (and why so few)
---------------------------
With dT_d the die temperature change read from the drive frequency (k_f fitted on the
training run, about -0.92 Hz/K) and a phase error expanded to first order,
phi(T) ~ phi0 + phi1 dT_d, the leak is Q phi0 + Q phi1 dT_d. The model is

    rate_err = c0 + c1 Q + c2 Q dT_d + c3 dT_d + c4 dT_d^2 + c5 A_agc

c1 and c2 are the leak through the phase (constant and temperature-dependent part), c3 and
c4 the remaining electronic temperature laws (offsets, reference drift) read on the die
thermometer, c5 the damping term. Six coefficients: every one has a physical reason, the
design stays well conditioned after standardising, and a model this small cannot learn a
training run's noise (an RBF or SVR on the same inputs could). No dT/dt term: with the die
thermometer there is no case-to-die lag left to imitate (the poly baseline needs dT/dt for
exactly that).

How it is applied
-----------------
The model is fitted by ordinary least squares on 1 s bin means of the training error
(``rate_dps - rate_true_dps``; the truth is taken as 0 when absent, i.e. a static run). The
regressors are 1 s bin means smoothed over ``smooth_s`` seconds (the auxiliary channels have
their own noise, which must not be injected into the output), interpolated back to the
record's time base, and the predicted drift is *subtracted* from ``rate_dps``. The signal
path is not filtered: the output is the input minus a slowly varying correction, so the
bandwidth and the white noise are those of the raw output (``filter_time_constant_s`` = 0 in
the diagnostics; the correction's own smoothing is ``correction_smoothing_s``).

Fallback
--------
Without the auxiliary channels (e.g. an imported record) the model falls back to temperature
alone, [dT, dT^2, dT/dt] on ``temperature_C`` (the poly baseline's regressors), with a
:class:`PhysicsFallbackWarning` and ``diagnostics_["fallback_temperature_only"] = True``.
With only some channels missing, the missing terms are dropped (die temperature from
``temperature_C`` when the drive frequency is missing) and the diagnostics list them.
Gaps (uneven steps) are handled: bins and derivatives use the actual times.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.ndimage import uniform_filter1d

from ..errors import InputError
from ..record import Record
from .base import Compensator, register
from .poly import bin_means, check_record, rate_error, thermal_features

#: Auxiliary channels the full model uses.
AUX_CHANNELS = ("quadrature_V", "drive_frequency_Hz", "agc_effort_V")
#: ``use_agc="auto"`` drops the AGC term when the die temperature explains it to R^2 > 1 - this.
AGC_COLLINEAR_TOL = 1e-3


class PhysicsFallbackWarning(UserWarning):
    """The physics compensator had to drop auxiliary terms (fallback to temperature)."""


def _smoothed_bins(t_s: np.ndarray, x: np.ndarray, smooth_s: float) -> tuple[np.ndarray, np.ndarray]:
    """1 s bin means of ``x`` smoothed by a centred moving average of ``smooth_s`` bins."""
    tb, xb = bin_means(t_s, x, 1.0)
    w = max(1, min(int(round(smooth_s)), len(xb)))
    if w > 1:
        xb = uniform_filter1d(xb, w, mode="nearest")
    return tb, xb


@register("physics")
class PhysicsCompensator(Compensator):
    """Least-squares drift model on quadrature, die temperature (drive frequency) and AGC effort.

    Parameters
    ----------
    smooth_s : float, optional
        Moving-average span of the regressors (1 s bin means), in s; sets the bandwidth of the
        correction, not of the signal.
    use_agc : {"auto", True, False}, optional
        Include the AGC-effort (damping) term. ``"auto"`` (default) includes it only when it
        carries information beyond the die temperature on the training run: when
        [dT_die, dT_die^2] explain it to R^2 > ``1 - AGC_COLLINEAR_TOL`` it is dropped (in the
        simulator's default device the damping is a function of temperature alone, and the
        collinear pair makes the coefficients swing by tens of deg/s in opposite directions).
    """

    handles_gaps = True

    def __init__(self, smooth_s: float = 30.0, use_agc="auto"):
        self.smooth_s = smooth_s
        self.use_agc = use_agc

    # -- regressors ----------------------------------------------------------------------------
    def _available(self, record: Record) -> dict:
        return {c: record.has(c) and bool(np.isfinite(record[c]).all()) for c in AUX_CHANNELS}

    def _columns(self, record: Record) -> tuple[np.ndarray, np.ndarray]:
        """(bin times, raw regressor columns on 1 s bins) for the terms in ``self.terms_``."""
        t = record.time_s
        if self.fallback_:
            X = thermal_features(t, record["temperature_C"], self.T_ref_C_, self.smooth_s)
            cols = [bin_means(t, X[:, k])[1] for k in range(3)]
            return bin_means(t, X[:, 0])[0], np.column_stack(cols)
        if self.die_source_ == "drive_frequency_Hz":
            tb, fb = _smoothed_bins(t, record["drive_frequency_Hz"], self.smooth_s)
            dTd = (fb - self.f_ref_Hz_) / self.kf_Hz_per_K_
        else:
            tb, Tb = _smoothed_bins(t, record["temperature_C"], self.smooth_s)
            dTd = Tb - self.T_ref_C_
        feats = {"dT_die": dTd, "dT_die^2": dTd * dTd}
        if "quadrature_V" in self.channels_:
            q = _smoothed_bins(t, record["quadrature_V"], self.smooth_s)[1] - self.q_ref_V_
            feats["Q"] = q
            feats["Q*dT_die"] = q * dTd
        if "agc_effort_V" in self.channels_:
            feats["A_agc"] = _smoothed_bins(t, record["agc_effort_V"], self.smooth_s)[1] - self.a_ref_V_
        return tb, np.column_stack([feats[k] for k in self.terms_])

    def _agc_r2(self, record: Record) -> float:
        """R^2 of the smoothed AGC effort on [1, dT_die, dT_die^2] (training record)."""
        t = record.time_s
        tb, fb = _smoothed_bins(t, record[self.die_source_], self.smooth_s)
        d = fb - fb.mean()
        a = _smoothed_bins(t, record["agc_effort_V"], self.smooth_s)[1]
        A = np.column_stack([np.ones(len(d)), d, d * d])
        r = a - A @ np.linalg.lstsq(A, a, rcond=None)[0]
        var = float(np.var(a))
        return 1.0 if var == 0 else float(1.0 - np.var(r) / var)

    def _design(self, record: Record) -> tuple[np.ndarray, np.ndarray]:
        tb, X = self._columns(record)
        return tb, (X - self.x_mean_) / self.x_scale_

    # -- estimator API ---------------------------------------------------------------------------
    def fit(self, record: Record) -> "PhysicsCompensator":
        """Fit the drift model on a training record.

        Parameters
        ----------
        record : Record
            Training data (``rate_true_dps`` used where known; a static run otherwise).

        Returns
        -------
        PhysicsCompensator
            ``self``, with ``coef_`` (deg/s per standardised regressor, intercept first),
            ``terms_``, ``fallback_`` and ``diagnostics_``.
        """
        check_record(record, need_uniform=False, min_samples=16, method=self.method_name)
        avail = self._available(record)
        t = record.time_s
        self.T_ref_C_ = float(np.mean(record["temperature_C"]))
        if self.use_agc not in ("auto", True, False):
            raise ValueError(f"use_agc must be 'auto', True or False, got {self.use_agc!r}")
        self.channels_ = [c for c in AUX_CHANNELS if avail[c] and (c != "agc_effort_V" or self.use_agc)]
        missing = [c for c in AUX_CHANNELS if not avail[c]]
        self.fallback_ = not any(avail.values())
        notes = []
        self.agc_r2_ = None
        if self.fallback_:
            self.terms_ = ["dT_case", "dT_case^2", "dTdt_case_C_per_min"]
            self.die_source_ = "temperature_C"
            msg = ("physics: the record has none of the auxiliary channels "
                   f"({', '.join(AUX_CHANNELS)}); falling back to a temperature-only model "
                   "[dT, dT^2, dT/dt] on temperature_C (it cannot see thermal lag or quadrature changes)")
            warnings.warn(msg, PhysicsFallbackWarning, stacklevel=2)
            notes.append(msg)
        else:
            if missing:
                msg = (f"physics: auxiliary channel(s) {', '.join(missing)} missing; their terms are dropped"
                       + ("; die temperature taken from temperature_C" if "drive_frequency_Hz" in missing else ""))
                warnings.warn(msg, PhysicsFallbackWarning, stacklevel=2)
                notes.append(msg)
            self.die_source_ = "drive_frequency_Hz" if avail["drive_frequency_Hz"] else "temperature_C"
            if self.die_source_ == "drive_frequency_Hz":
                tb, fb = bin_means(t, record["drive_frequency_Hz"])
                Tb = bin_means(t, record["temperature_C"])[1]
                self.f_ref_Hz_ = float(np.mean(fb))
                slope = np.polyfit(Tb - Tb.mean(), fb, 1)[0] if np.ptp(Tb) > 1.0 else 0.0
                if abs(slope) < 1e-3:  # soak or no usable temperature span: nominal coefficient
                    slope = -0.92
                    notes.append("drive-frequency temperature coefficient not identifiable on the "
                                 "training run (span < 1 K): nominal -0.92 Hz/K used (only scales dT_die)")
                self.kf_Hz_per_K_ = float(slope)
            self.q_ref_V_ = float(np.mean(record["quadrature_V"])) if "quadrature_V" in self.channels_ else 0.0
            self.a_ref_V_ = float(np.mean(record["agc_effort_V"])) if "agc_effort_V" in self.channels_ else 0.0
            self.terms_ = ["dT_die", "dT_die^2"]
            if "agc_effort_V" in self.channels_ and self.use_agc == "auto":
                self.agc_r2_ = self._agc_r2(record)
                if self.agc_r2_ > 1.0 - AGC_COLLINEAR_TOL:
                    self.channels_.remove("agc_effort_V")
                    notes.append(f"agc_effort_V dropped: the die temperature explains it to R^2 = {self.agc_r2_:.5f} "
                                 "on the training run (no independent information; collinear terms would make "
                                 "the fit ill-conditioned)")
            if "quadrature_V" in self.channels_:
                self.terms_ += ["Q", "Q*dT_die"]
            if "agc_effort_V" in self.channels_:
                self.terms_ += ["A_agc"]
        self.x_mean_, self.x_scale_ = 0.0, 1.0
        _, X = self._columns(record)
        self.x_mean_ = X.mean(axis=0)
        sd = X.std(axis=0)
        self.x_scale_ = np.where(sd > 0, sd, 1.0)
        Xs = (X - self.x_mean_) / self.x_scale_
        yb = bin_means(t, rate_error(record))[1]
        A = np.column_stack([np.ones(len(Xs)), Xs])
        self.coef_, *_ = np.linalg.lstsq(A, yb, rcond=None)
        resid = yb - A @ self.coef_
        self.diagnostics_ = {
            "method": self.method_name, "terms": ["1"] + list(self.terms_),
            "coef_dps_per_sd": self.coef_.tolist(), "fallback_temperature_only": self.fallback_,
            "channels_used": list(self.channels_), "channels_missing": missing,
            "die_temperature_source": self.die_source_,
            "drive_frequency_tc_Hz_per_K": getattr(self, "kf_Hz_per_K_", None),
            "fit_residual_rms_1s_dph": float(np.sqrt(np.mean(resid ** 2)) * 3600.0),
            "condition_number": float(np.linalg.cond(A)), "bins_1s": len(yb),
            "agc_r2_on_die_temperature": self.agc_r2_,
            "filter_time_constant_s": 0.0, "correction_smoothing_s": float(self.smooth_s),
            "notes": notes,
        }
        return self

    def transform(self, record: Record) -> np.ndarray:
        """Rate with the predicted drift subtracted (signal path untouched), in deg/s.

        Parameters
        ----------
        record : Record
            Record to compensate; it must carry the channels the model was fitted with.

        Returns
        -------
        ndarray
        """
        check_record(record, need_uniform=False, min_samples=2, method=self.method_name)
        avail = self._available(record)
        need = [] if self.fallback_ else list(self.channels_)
        lacking = [c for c in need if not avail[c]]
        if lacking:
            raise InputError(f"channel(s) {', '.join(lacking)} missing or incomplete, but the physics model "
                             "was fitted with them; refit on a record without them (temperature fallback)",
                             record.path or "record")
        return record["rate_dps"] - self.drift(record)

    def drift(self, record: Record) -> np.ndarray:
        """The predicted drift in deg/s on the record's time base.

        Parameters
        ----------
        record : Record

        Returns
        -------
        ndarray
        """
        tb, Xs = self._design(record)
        pred_b = self.coef_[0] + Xs @ self.coef_[1:]
        if len(tb) == 1:
            return np.full(len(record), pred_b[0])
        return np.interp(record.time_s, tb, pred_b)
