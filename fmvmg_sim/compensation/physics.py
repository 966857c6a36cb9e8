"""The ``physics`` compensator: a drift model on the gyro's own auxiliary channels.

Where the drift comes from
--------------------------
In an open-loop vibratory gyro the zero-rate output is mostly quadrature leaking into the
rate channel through a phase error between the sense signal and the demodulation
reference: rate_err ~ Q * sin(phi(T)) + (damping asymmetry ~ 1/Q_factor) + small
electronic offsets. The record carries the quantities this needs, measured by the gyro
itself rather than by a thermometer glued to the case:

* ``quadrature_V``: the quadrature amplitude Q that leaks;
* ``drive_frequency_Hz``: the drive resonance moves with the die temperature (its slope
  comes from the device file named in the record's ``# device:`` line,
  :attr:`fmvmg_sim.device.Device.drive_frequency_tc_Hz_per_K`), so it is the die's own thermometer and follows the die through any case-to-die lag;
* ``agc_effort_V``: the drive-amplitude control effort, proportional to the drive damping.

Model and its selection
-----------------------
The MEMS element's laws (resonances, quadrature, damping) follow the die; the electronics
(amplifier bandwidths, phase shifter, reference, rectifier) sit on the board, at the case
temperature that ``temperature_C`` reads. With dT_die the die temperature change read from the
drive frequency and dT_case the change of ``temperature_C``, the candidate models are least
squares on 1 s bin means of the training error of

    rate_err = c0 + c3 dT_die [+ c4 dT_die^2] [+ c1 Q [+ c2 Q dT_die]] [+ c5 A_agc]
               [+ c6 dT_case [+ c7 dT_case^2]]

(c1, c2: the leak through a phase expanded to first order in temperature; c3, c4: the other
temperature laws on the die's thermometer; c5: the damping term; c6, c7: the electronics' laws
on the case), each with the auxiliary channels smoothed over one of ``smoothing_s`` (their own
noise must not reach the output), beside the temperature models of :mod:`.thermal_model` on
``temperature_C``. Which one is used is chosen by forward-chained validation on the training
record (:mod:`.selection`): on a record whose auxiliary channels carry nothing the temperature
does not, a temperature model wins and the report says so. The AGC term is left out beforehand
when the die temperature explains the AGC effort to R^2 > 1 - :data:`AGC_COLLINEAR_TOL`
(collinear columns make the coefficients swing). Without the drive frequency the die and case
temperatures are the same reading and the case terms are not offered.

How it is applied
-----------------
The regressors are computed on 1 s bins of the record (inside the stretches between gaps),
the predicted drift is interpolated back to the samples and *subtracted* from ``rate_dps``.
The signal path is not filtered (``filter_time_constant_s`` = 0 in the diagnostics; the
correction's own smoothing is ``correction_smoothing_s``). The regressors all follow the
temperature, so in training they are nearly collinear: their coefficients are pinned down along
the data and not across it. Beyond the range seen in training the model is therefore evaluated
at the training point nearest in all its regressors (a combination the data fixed, not a
clamped corner of the box) and continued from there along its tangent plane, when the drift's
slope along the regressors' principal direction is reproducible over the record's time blocks
(:func:`.selection.principal_slope_significance`); otherwise it is held there. The transform
diagnostics say which channels left the range and by how much.

Fallback
--------
Without any auxiliary channel (e.g. an imported record) the model *is* the temperature model
(the ``poly-baseline`` selection), with a :class:`PhysicsFallbackWarning` and
``diagnostics_["fallback_temperature_only"] = True``. With only some channels missing, their
terms are dropped (die temperature from ``temperature_C`` when the drive frequency is
missing) and the diagnostics list them.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from sklearn.utils.validation import check_is_fitted

from ..device import Device, load_device
from ..errors import InputError
from ..paths import devices_dir
from ..record import Record
from .base import Compensator, register
from .poly import check_record, complete_rows, rate_error
from .segments import Bins, describe, make_bins, smooth_within
from .selection import Candidate, chained_folds, select, time_blocks
from .thermal_model import UNITS, TemperatureModel, summarise_extrapolation

#: Auxiliary channels the full model uses.
AUX_CHANNELS = ("quadrature_V", "drive_frequency_Hz", "agc_effort_V")
#: ``use_agc="auto"`` drops the AGC term when the die temperature explains it to R^2 > 1 - this.
AGC_COLLINEAR_TOL = 1e-3
#: Smoothing spans of the auxiliary channels offered by default, in s.
SMOOTHING_S = (10.0, 30.0, 120.0)
#: Base variables of the auxiliary models and their units.
AUX_VARS = ["Q", "dT_die", "A_agc", "dT_case"]
AUX_UNITS = {"Q": "V", "dT_die": "K", "A_agc": "V", "dT_case": "K", **UNITS}


class PhysicsFallbackWarning(UserWarning):
    """The physics compensator had to drop auxiliary terms (fallback to temperature)."""


def find_device(name: str) -> Device | None:
    """The shipped device whose name (or file stem) is ``name``, or a device file at that path.

    Parameters
    ----------
    name : str
        A record's ``# device:`` value (``fmvmg-a``), a shipped file stem (``fmvmg_a``) or a path.

    Returns
    -------
    Device or None
        None when nothing matches.
    """
    p = Path(name)
    if p.suffix == ".toml" and p.is_file():
        return load_device(p)
    for f in sorted(devices_dir().glob("*.toml")):
        if f.stem in (name, name.replace("-", "_")):
            return load_device(f)
    for f in sorted(devices_dir().glob("*.toml")):
        dev = load_device(f)
        if dev.name == name:
            return dev
    return None


@register("physics")
class PhysicsCompensator(Compensator):
    """Least-squares drift model on quadrature, die temperature (drive frequency) and AGC effort.

    Parameters
    ----------
    smoothing_s : tuple of float, optional
        Moving-average spans of the auxiliary channels to choose from, in s (they set the
        bandwidth of the correction, not of the signal).
    use_agc : {"auto", True, False}, optional
        Offer the AGC-effort (damping) term. ``"auto"`` offers it only when it carries
        information beyond the die temperature on the training run (R^2 of the AGC effort on
        [dT_die, dT_die^2] below ``1 - AGC_COLLINEAR_TOL``).
    temperature_models : bool, optional
        Also offer the temperature models of ``poly-baseline`` to the selection.
    device : str, optional
        Device name or file for the drive-frequency slope (default: the record's
        ``# device:`` line).
    rule : {"best", "one-se"}, optional
        Selection rule (:func:`.selection.select`).
    n_folds : int, optional
        Forward-chained validation folds.
    min_train_fraction : float, optional
        Fraction of the training record the first fold is fitted on.
    case_orders : tuple of int, optional
        Orders of the case-temperature (electronics) terms to choose from (0: none).
    """

    handles_gaps = True

    def __init__(self, smoothing_s=SMOOTHING_S, use_agc="auto", temperature_models=True, device=None,
                 rule="best", n_folds=4, min_train_fraction=0.5, case_orders=(0, 1, 2)):
        self.smoothing_s, self.use_agc, self.temperature_models = smoothing_s, use_agc, temperature_models
        self.case_orders = case_orders
        self.device, self.rule, self.n_folds, self.min_train_fraction = device, rule, n_folds, min_train_fraction

    # -- regressors ----------------------------------------------------------------------------
    @staticmethod
    def _available(record: Record) -> dict:
        return {c: record.has(c) and bool(np.isfinite(record[c]).all()) for c in AUX_CHANNELS}

    def _aux_base(self, record: Record, bins: Bins, span: float) -> np.ndarray:
        """[Q, dT_die, A_agc, dT_case] per bin (columns of missing channels are zeros)."""
        def sm(c):
            return smooth_within(bins, bins.mean(record[c]), span)
        dTc = sm("temperature_C") - self.T_ref_C_
        if self.die_source_ == "drive_frequency_Hz":
            dTd = (sm("drive_frequency_Hz") - self.f_ref_Hz_) / self.kf_Hz_per_K_
        else:
            dTd = dTc
        z = np.zeros(len(bins))
        q = sm("quadrature_V") - self.q_ref_V_ if "quadrature_V" in self.channels_ else z
        a = sm("agc_effort_V") - self.a_ref_V_ if "agc_effort_V" in self.channels_ else z
        return np.column_stack([q, dTd, a, dTc])

    def _base(self, record: Record, bins: Bins, key) -> np.ndarray:
        kind, span = key
        if kind == "aux":
            return self._aux_base(record, bins, span)
        return self.tmodel_.base(bins, bins.mean(record["temperature_C"]), span)

    def _aux_candidates(self) -> list[Candidate]:
        has_q, has_a = "quadrature_V" in self.channels_, "agc_effort_V" in self.channels_
        # the case temperature is a second thermometer only when the die's is the drive frequency
        case_orders = tuple(self.case_orders) if self.die_source_ == "drive_frequency_Hz" else (0,)
        out = []
        for span in self.smoothing_s:
            for die in (1, 2):
                for nq in ((0, 1, 2) if has_q else (0,)):
                    for na in ((0, 1) if has_a else (0,)):
                        for nc in case_orders:
                            e = [(0, k, 0, 0) for k in range(1, die + 1)]
                            e += [(1, 0, 0, 0), (1, 1, 0, 0)][:nq] + [(0, 0, 1, 0)][:na]
                            e += [(0, 0, 0, k) for k in range(1, nc + 1)]
                            name = " + ".join(["dT_die" if die == 1 else "dT_die, dT_die^2"]
                                              + ["Q", "Q, Q*dT_die"][nq - 1:nq] + ["A_agc"][:na]
                                              + ["dT_case", "dT_case, dT_case^2"][nc - 1:nc])
                            out.append(Candidate(f"{name} ({span:g} s)", ("aux", span), AUX_VARS, e,
                                                 {"die_order": die, "quadrature_terms": nq, "agc_term": bool(na),
                                                  "case_order": nc, "smoothing_s": span, "held": [],
                                                  "anchor": True, "continuation": "tangent",
                                                  "slope_test": "joint"}))
        return out

    def _agc_r2(self, record: Record, bins: Bins) -> float:
        """R^2 of the smoothed AGC effort on [1, dT_die, dT_die^2] (training record)."""
        X = self._aux_base(record, bins, self.smoothing_s[0])
        d, a = X[:, 1], X[:, 2]
        A = np.column_stack([np.ones(len(d)), d, d * d])
        r = a - A @ np.linalg.lstsq(A, a, rcond=None)[0]
        var = float(np.var(a))
        return 1.0 if var == 0 else float(1.0 - np.var(r) / var)

    def _drive_slope(self, record: Record, bins: Bins, notes: list) -> tuple[float, str]:
        name = self.device or record.metadata.get("device")
        dev = find_device(name) if name else None
        if dev is not None:
            return dev.drive_frequency_tc_Hz_per_K, f"device file {dev.name!r} (Device.drive_frequency_tc_Hz_per_K)"
        Tb, fb = bins.mean(record["temperature_C"]), bins.mean(record["drive_frequency_Hz"])
        if np.ptp(Tb) > 1.0:
            slope = float(np.polyfit(Tb - Tb.mean(), fb, 1)[0])
            if abs(slope) > 1e-6:
                notes.append(f"device {name!r} unknown: drive-frequency slope fitted on the training run"
                             if name else "no device named: drive-frequency slope fitted on the training run")
                return slope, "fitted on the training run (drive frequency against temperature_C)"
        notes.append("drive-frequency slope unknown (no device file, temperature span < 1 K): dT_die is "
                     "the drive-frequency change in Hz (the fit is unaffected; ranges are in Hz)")
        return 1.0, "unknown: dT_die in Hz"

    # -- estimator API ---------------------------------------------------------------------------
    def fit(self, record: Record) -> "PhysicsCompensator":
        """Choose and fit the drift model on a training record.

        Parameters
        ----------
        record : Record
            Training data (``rate_true_dps`` used where known; a static run otherwise).

        Returns
        -------
        PhysicsCompensator
            ``self``, with ``model_``, ``key_`` (which regressors), ``terms_``, ``fallback_`` and
            ``diagnostics_`` (the selection with every option's validation score).
        """
        check_record(record, need_uniform=False, min_samples=16, method=self.method_name, allow_missing=True)
        record, _, gap_note = complete_rows(record)
        if self.use_agc not in ("auto", True, False):
            raise ValueError(f"use_agc must be 'auto', True or False, got {self.use_agc!r}")
        avail = self._available(record)
        t = record.time_s
        bins = make_bins(t)
        self.T_ref_C_ = float(np.average(bins.mean(record["temperature_C"]), weights=bins.counts))
        self.channels_ = [c for c in AUX_CHANNELS if avail[c] and (c != "agc_effort_V" or self.use_agc)]
        missing = [c for c in AUX_CHANNELS if not avail[c]]
        self.fallback_ = not any(avail.values())
        notes, self.agc_r2_, self.kf_Hz_per_K_, kf_source = [gap_note] if gap_note else [], None, None, None
        self.tmodel_ = TemperatureModel(n_folds=self.n_folds, min_train_fraction=self.min_train_fraction,
                                        rule=self.rule)
        if self.fallback_:
            msg = ("physics: the record has none of the auxiliary channels "
                   f"({', '.join(AUX_CHANNELS)}); falling back to a temperature-only model, the one "
                   "poly-baseline selects (it cannot see a case-to-die lag or quadrature changes)")
            warnings.warn(msg, PhysicsFallbackWarning, stacklevel=2)
            notes.append(msg)
            self.tmodel_.fit(t, record["temperature_C"], rate_error(record))
            self.key_, self.model_, sel = ("T", self.tmodel_.span_), self.tmodel_.model_, self.tmodel_.selection_
            self.die_source_ = "temperature_C"
        else:
            if missing:
                msg = (f"physics: auxiliary channel(s) {', '.join(missing)} missing; their terms are dropped"
                       + ("; die temperature taken from temperature_C" if "drive_frequency_Hz" in missing else ""))
                warnings.warn(msg, PhysicsFallbackWarning, stacklevel=2)
                notes.append(msg)
            self.die_source_ = "drive_frequency_Hz" if avail["drive_frequency_Hz"] else "temperature_C"
            if self.die_source_ == "drive_frequency_Hz":
                self.f_ref_Hz_ = float(np.average(bins.mean(record["drive_frequency_Hz"]), weights=bins.counts))
                self.kf_Hz_per_K_, kf_source = self._drive_slope(record, bins, notes)
            self.q_ref_V_ = float(np.mean(record["quadrature_V"])) if "quadrature_V" in self.channels_ else 0.0
            self.a_ref_V_ = float(np.mean(record["agc_effort_V"])) if "agc_effort_V" in self.channels_ else 0.0
            if "agc_effort_V" in self.channels_ and self.use_agc == "auto":
                self.agc_r2_ = self._agc_r2(record, bins)
                if self.agc_r2_ > 1.0 - AGC_COLLINEAR_TOL:
                    self.channels_.remove("agc_effort_V")
                    notes.append(f"agc_effort_V not offered: the die temperature explains it to R^2 = "
                                 f"{self.agc_r2_:.5f} on the training run (collinear terms would make the fit "
                                 "ill-conditioned)")
            cands = self._aux_candidates()
            sampling = describe(t)
            if self.temperature_models:
                self.tmodel_.T_ref_C_ = self.T_ref_C_
                spans, note = self.tmodel_.offered_spans(bins)
                notes += [note] if note else []
                cands += [Candidate(f"temperature: {c.name}", ("T", c.key), c.var_names, c.exponents,
                                    {"temperature_model": True, **c.settings})
                          for c in self.tmodel_.candidates(spans)]
            base = {c.key: self._base(record, bins, c.key) for c in cands}
            folds = chained_folds(bins, self.n_folds, self.min_train_fraction, by_segment=sampling["bursty"])
            yb = bins.mean(rate_error(record))
            rv = [bins.mean(record["temperature_C"]) - self.T_ref_C_]
            if self.die_source_ == "drive_frequency_Hz":
                rv.append(self._aux_base(record, bins, self.smoothing_s[0])[:, 1])
            sel = select(cands, base, yb, bins.counts, folds, bins.t_s, self.rule, range_vars=np.column_stack(rv),
                         blocks=time_blocks(bins, 8, sampling["bursty"]))
            self.key_ = sel.chosen.key
            self.model_ = sel.chosen.model().fit(base[self.key_], yb, bins.counts)
            if self.key_[0] == "T":
                self.tmodel_.span_, self.tmodel_.model_ = self.key_[1], self.model_
                notes.append("the validation chose a temperature model: the auxiliary channels did not "
                             "forecast the drift better than temperature_C on the training record")
        self.terms_ = self.model_.terms
        self.diagnostics_ = {
            "method": self.method_name, "terms": list(self.terms_), "coef": self.model_.coefficients(),
            "selection": sel.report(), "fallback_temperature_only": self.fallback_,
            "model_family": "temperature" if self.key_[0] == "T" else "auxiliary channels",
            "channels_used": list(self.channels_) if self.key_[0] == "aux" else ["temperature_C"],
            "channels_missing": missing, "die_temperature_source": self.die_source_,
            "drive_frequency_tc_Hz_per_K": self.kf_Hz_per_K_, "drive_frequency_tc_source": kf_source,
            "agc_r2_on_die_temperature": self.agc_r2_, "sampling": describe(t),
            "condition_number": self.model_.condition_number_, "bins_1s": len(bins),
            "filter_time_constant_s": 0.0,
            "correction_smoothing_s": self.key_[1] if self.key_[0] == "aux" else self.key_[1] or 0.0,
            "beyond_training_range": {"continuation": self.model_.continuation, "held": list(self.model_.held)},
            "notes": notes + sel.notes}
        return self

    def compensate_rate_dps(self, record: Record) -> np.ndarray:
        """Rate with the predicted drift subtracted (signal path untouched), in deg/s.

        Parameters
        ----------
        record : Record
            Record to compensate; it must carry the channels the model was fitted with.

        Returns
        -------
        ndarray
            ``transform_diagnostics_["extrapolation"]`` says which regressors left the training
            box and by how much.
        """
        check_is_fitted(self, "model_")
        check_record(record, need_uniform=False, min_samples=1, method=self.method_name, allow_missing=True)
        full, (record, keep, gap_note) = record, complete_rows(record)
        avail = self._available(record)
        need = list(self.channels_) if self.key_[0] == "aux" else []
        lacking = [c for c in need if not avail[c]]
        if lacking:
            raise InputError(f"channel(s) {', '.join(lacking)} missing or incomplete, but the physics model "
                             "was fitted with them; refit on a record without them (temperature fallback)",
                             record.path or "record")
        bins = make_bins(record.time_s)
        X = self._base(record, bins, self.key_)
        ex = self.model_.extrapolation(X, bins.counts, AUX_UNITS)
        ex["summary"] = summarise_extrapolation(ex)
        off = self.model_.off_data(X)[0]
        if off.any():
            ex["off_training_data_fraction"] = float(bins.counts[off].sum() / bins.counts.sum())
            ex["summary"] += (f"; there ({100 * ex['off_training_data_fraction']:.0f} % of the record) the model takes "
                              "its value at the training point nearest in its regressors, continued from there")
        self.transform_diagnostics_ = {"extrapolation": ex, "sampling": describe(record.time_s),
                                       "filter_time_constant_s": 0.0, "notes": [gap_note] if gap_note else []}
        out = np.full(len(full), np.nan)
        out[keep] = record["rate_dps"] - bins.to_samples(record.time_s, self.model_.predict(X))
        return out

    def drift(self, record: Record) -> np.ndarray:
        """The predicted drift in deg/s on the record's time base.

        Parameters
        ----------
        record : Record

        Returns
        -------
        ndarray
        """
        check_is_fitted(self, "model_")
        full, (record, keep, _) = record, complete_rows(record)
        bins = make_bins(record.time_s)
        out = np.full(len(full), np.nan)
        out[keep] = bins.to_samples(record.time_s, self.model_.predict(self._base(record, bins, self.key_)))
        return out
