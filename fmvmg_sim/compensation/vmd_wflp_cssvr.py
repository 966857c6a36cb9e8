"""Paper 004's parallel model, ``vmd-wflp-cssvr`` (section 3.5, Figure 5).

rate -> VMD (K = 6, alpha = 2000, tau = 0) -> sample entropy per mode -> noise / mixed /
drift classes (calibrated thresholds of :mod:`.vmd_classes`, not the paper's unreachable
4.2 and 2) -> noise modes dropped; the sum of the mixed modes denoised by WFLP; the sum of
the drift modes minus a CS-SVR model of drift on ``[T, dT/dt]`` -> output = denoised mixed
+ compensated drift + the VMD residual treated by ``residual``:

* ``"keep"`` (default): the residual ``y - sum(u_k)`` is added back unchanged, so nothing
  is silently dropped (with tau = 0 it holds about 43 % of a gyro record's SD);
* ``"wflp"``: it is added back after WFLP denoising;
* ``"drop"``: it is discarded (what reconstructing from the modes alone, as the paper
  does, amounts to; reported in the diagnostics as ``residual_fraction``).

The class roles follow the paper's section 3.5 (noise removed, mixed denoised, drift
compensated); its section 4.2 contradicts itself, "wiping off" C1, which it had called
the drift feature, and compensating C3, which it had called noise-only.

``fit(train)`` decomposes the training rate error (``rate_dps - rate_true_dps`` where the
truth is known) and fits the CS-SVR on its drift modes, so tuning never sees the record
it is evaluated on unless the caller passes the same record. ``transform(record)``
decomposes the record and applies the model. When a decomposition has no drift mode
no model is fitted or nothing is subtracted, and the diagnostics say so. Needs even
sampling; refuses gaps.

Sample rate: decimated decomposition, full-rate output
------------------------------------------------------
At the simulator's 100 Hz no VMD mode holds the thermal drift (:mod:`.vmd_classes`: with
alpha = 2000 a mode is about fs/sqrt(alpha) = 2.2 Hz wide, so the lowest mode spans
0-2 Hz and the drift is 4 % of it), every mode is called noise and dropped, and the method
returns the residual alone: it compensates nothing and throws away about half of the
signal. Scaling alpha with fs would instead need alpha ~ 1e7 at 100 Hz and a VMD
that converges over millions of samples. So the decomposition runs on a decimated copy:

* ``decimate_Hz`` (default 1.0; ``None`` = run at the native rate) -- the record is
  averaged over blocks of ``round(fs / decimate_Hz)`` samples (the last partial block is
  left out of the decomposition), and the whole paper-004 chain (VMD, classes, WFLP,
  CS-SVR) runs on that copy, where the drift owns the lowest mode as the paper assumes;
* the low-rate correction ``c = y_low - out_low`` is interpolated (linearly, at the block
  centres) to the full time base and subtracted: ``out = y - interp(c)``. What lies above
  the low rate's Nyquist frequency, ``y - interp(y_low)``, is kept unchanged and explicitly:
  the full-rate output is ``interp(out_low) + (y - interp(y_low))``, the same thing.
  ``carry_back="all"`` (default, the paper's chain) carries back everything the low-rate
  chain removed (dropped noise modes, WFLP denoising, drift model), so the method still
  filters the band of the dropped modes (up to ``decimate_Hz / 2``);
  ``carry_back="drift"`` carries back the CS-SVR drift prediction alone (a pure drift
  subtraction that keeps the whole signal band).

``transform_diagnostics_["filter_time_constant_s"]`` is the longest time constant of what
the chain removes or filters, 1 / (2 pi f) at the lowest centre frequency among dropped and
WFLP-filtered modes (0 for ``carry_back="drift"``), for reading the Allan bias instability
only where filtering cannot reach. Measured effect (``benchmarks/compensation_eval.py``,
docs/compensation_results.md): at 100 Hz without decimation the method leaves the thermal
drift in place; with 1 Hz decimation it fits a drift mode and subtracts the CS-SVR model.
"""

from __future__ import annotations

import numpy as np

from sklearn.utils.validation import check_is_fitted

from ..errors import InputError
from ..record import Record
from .base import Compensator, register
from .cssvr import CSSVR, temperature_features
from .poly import check_record, rate_error
from .selection import box_extrapolation
from .thermal_model import TemperatureModel
from .sampen import CLASS_NAMES, DRIFT, MIXED, NOISE
from .vmd import vmd
from .vmd_classes import DRIFT_SE_MAX, NOISE_SE_MIN, classify_modes, mode_entropies
from .wflp import wflp

#: Fewest samples accepted (WFLP at level 4 with db4, 5-fold time-series CV).
MIN_SAMPLES = 256
RESIDUAL_POLICIES = ("keep", "wflp", "drop")
#: Names of the CS-SVR's candidate inputs (columns of :func:`.cssvr.temperature_features`).
INPUT_NAMES = ("temperature_C", "dTdt_C_per_min")
CARRY_BACK_POLICIES = ("all", "drift")


@register("vmd-wflp-cssvr")
class VMDWFLPCSSVR(Compensator):
    """VMD + sample-entropy classes + WFLP on mixed modes + CS-SVR on drift modes.

    Parameters
    ----------
    K, alpha, tau, tol, max_iter : optional
        VMD settings (compensation.md section 5).
    noise_se_min, drift_se_max : float, optional
        Sample-entropy class thresholds (calibrated defaults of :mod:`.vmd_classes`).
    wavelet, wavelet_level, flp_order : optional
        WFLP settings.
    search, budget, n_nests, n_max, seed : optional
        CS-SVR search (``"cuckoo"``, ``"grid"`` or ``"de"``), evaluation budget, nests,
        training points after block averaging, seed.
    smooth_s : float, optional
        Temperature smoothing before dT/dt, in s.
    residual : {"keep", "wflp", "drop"}, optional
        What happens to the VMD residual (module docstring).
    progress : bool, optional
        Show the CS-SVR search's progress bar on stderr.
    decimate_Hz : float or None, optional
        Run the chain on block means at this rate and carry the correction back to the
        record's rate (module docstring); None or a rate >= half the record's: native rate.
    carry_back : {"all", "drift"}, optional
        What the full-rate output takes from the low-rate chain (module docstring).
    """

    handles_gaps = False

    def __init__(self, K=6, alpha=2000.0, tau=0.0, tol=1e-7, max_iter=500, noise_se_min=NOISE_SE_MIN,
                 drift_se_max=DRIFT_SE_MAX, wavelet="db4", wavelet_level=4, flp_order=8, search="cuckoo",
                 budget=1515, n_nests=15, n_max=2000, seed=0, smooth_s=60.0, residual="keep",
                 progress=False, decimate_Hz=1.0, carry_back="all"):
        self.K, self.alpha, self.tau, self.tol, self.max_iter = K, alpha, tau, tol, max_iter
        self.noise_se_min, self.drift_se_max = noise_se_min, drift_se_max
        self.wavelet, self.wavelet_level, self.flp_order = wavelet, wavelet_level, flp_order
        self.search, self.budget, self.n_nests, self.n_max, self.seed = search, budget, n_nests, n_max, seed
        self.smooth_s, self.residual, self.progress = smooth_s, residual, progress
        self.decimate_Hz, self.carry_back = decimate_Hz, carry_back

    def _check(self, record: Record) -> float:
        if self.residual not in RESIDUAL_POLICIES:
            raise ValueError(f"residual must be one of {RESIDUAL_POLICIES}, got {self.residual!r}")
        check_record(record, need_uniform=True, min_samples=MIN_SAMPLES, method=self.method_name)
        return 1.0 / record.sample_interval_s()

    def _decompose(self, y: np.ndarray, fs: float):
        res = vmd(y, K=self.K, alpha=self.alpha, tau=self.tau, tol=self.tol, max_iter=self.max_iter)
        ent = mode_entropies(res.modes)
        cls = classify_modes(ent, self.noise_se_min, self.drift_se_max)
        groups = {c: res.modes[cls == c].sum(axis=0) if np.any(cls == c) else np.zeros_like(y)
                  for c in (NOISE, MIXED, DRIFT)}
        var = float(np.var(y)) or 1.0
        diag = {"centre_frequencies_Hz": res.centre_frequencies_Hz(fs).tolist(),
                "sample_entropy": ent.tolist(), "classes": [CLASS_NAMES[c] for c in cls],
                "vmd_iterations": res.iterations, "vmd_converged": res.converged,
                "residual_fraction": res.residual_fraction(),
                "dropped_noise_variance_fraction": float(np.var(groups[NOISE]) / var),
                "thresholds": {"noise_se_min": self.noise_se_min, "drift_se_max": self.drift_se_max}}
        return res, cls, groups, diag

    def _features(self, record: Record) -> np.ndarray:
        X = temperature_features(record.time_s, record["temperature_C"], self.smooth_s)
        return X[:, list(self.input_cols_)]

    # -- decimation ---------------------------------------------------------------------------
    def _block(self, record: Record) -> int:
        """Samples per decimation block (1 = native rate)."""
        if self.carry_back not in CARRY_BACK_POLICIES:
            raise ValueError(f"carry_back must be one of {CARRY_BACK_POLICIES}, got {self.carry_back!r}")
        if self.decimate_Hz is None:
            return 1
        if not self.decimate_Hz > 0:
            raise ValueError(f"decimate_Hz must be positive or None, got {self.decimate_Hz!r}")
        check_record(record, need_uniform=True, min_samples=2, method=self.method_name)
        fs = 1.0 / record.sample_interval_s()
        return max(1, int(round(fs / self.decimate_Hz))) if fs >= 2.0 * self.decimate_Hz else 1

    def _low(self, record: Record, m: int) -> Record:
        """Block means over ``m`` samples (whole blocks only) of the channels the chain uses."""
        n = len(record) // m * m
        if n // m < MIN_SAMPLES:
            raise InputError(f"record has {len(record)} rows = {n // m} blocks of {m} at {self.decimate_Hz:g} Hz; "
                             f"method {self.method_name!r} needs at least {MIN_SAMPLES} blocks (a longer record, "
                             "or a higher decimate_Hz)", record.path or "record")
        cols = {c: record[c][:n].reshape(-1, m).mean(axis=1)
                for c in ("time_s", "temperature_C", "rate_dps", "rate_true_dps") if c in record}
        if "rate_true_dps" in cols and not np.isfinite(cols["rate_true_dps"]).all():
            del cols["rate_true_dps"]
        return Record(cols, dict(record.metadata), record.path)

    def fit(self, record: Record) -> "VMDWFLPCSSVR":
        """Fit on the decimated copy (or natively) -- see :meth:`_fit_native`.

        Parameters
        ----------
        record : Record
            Training record (even steps).

        Returns
        -------
        VMDWFLPCSSVR
            ``self``; ``block_`` is the decimation factor used.
        """
        self._check_policy()
        m = self._block(record)
        self.block_ = m
        if m == 1:
            return self._fit_native(record)
        self._fit_native(self._low(record, m))
        self.fit_diagnostics_.update({"decimated_to_Hz": self.fit_diagnostics_["fs_Hz"], "decimation_block": m,
                                      "n_samples_full_rate": len(record)})
        return self

    def compensate_rate_dps(self, record: Record) -> np.ndarray:
        """Compensated rate in deg/s at the record's own rate -- see :meth:`_transform_native`.

        Parameters
        ----------
        record : Record
            Record to compensate (even steps).

        Returns
        -------
        ndarray
            With decimation: ``rate_dps`` minus the low-rate correction interpolated to the full
            time base (the band above the low rate's Nyquist frequency passes unchanged).
        """
        check_is_fitted(self, "block_")
        self._check_policy()
        m = self._block(record)
        if m == 1:
            out = self._transform_native(record)
            self.transform_diagnostics_["filter_time_constant_s"] = self._time_constant(
                self.transform_diagnostics_, 1.0 / record.sample_interval_s())
            return out
        low = self._low(record, m)
        out_low = self._transform_native(low)
        d = self.transform_diagnostics_
        y = np.asarray(record["rate_dps"], dtype=float)
        if self.carry_back == "all":
            corr_low = low["rate_dps"] - out_low
        else:
            corr_low = self._drift_pred_ if self._drift_pred_ is not None else np.zeros(len(low))
        corr = np.interp(record.time_s, low.time_s, corr_low)
        hf = y - np.interp(record.time_s, low.time_s, low["rate_dps"])
        d.update({"decimated_to_Hz": d.get("fs_Hz", 1.0 / low.sample_interval_s()), "decimation_block": m,
                  "carry_back": self.carry_back,
                  "full_rate_residual_rms_dps": float(np.std(hf)),
                  "full_rate_residual_note": "y - interp(block means): the band above the low rate's Nyquist "
                                             "frequency, passed through unchanged",
                  "correction_rms_dps": float(np.std(corr)),
                  "filter_time_constant_s": 0.0 if self.carry_back == "drift"
                  else max(float(m) / (1.0 / record.sample_interval_s()) / (2 * np.pi),
                           self._time_constant(d, 1.0 / low.sample_interval_s()))})
        return y - corr

    def _check_policy(self) -> None:
        if self.carry_back not in CARRY_BACK_POLICIES:
            raise ValueError(f"carry_back must be one of {CARRY_BACK_POLICIES}, got {self.carry_back!r}")

    def _time_constant(self, diag: dict, fs: float) -> float:
        """1 / (2 pi f_min) over the modes the chain drops or filters (0 when none)."""
        fc = np.asarray(diag.get("centre_frequencies_Hz", []), dtype=float)
        cls = diag.get("classes", [])
        filt = [f for f, c in zip(fc, cls) if c in ("noise", "mixed")]
        if self.residual != "keep":
            filt.append(fs / 4.0)  # residual dropped or filtered: broadband, take mid-band
        if not filt:
            return 0.0
        tc = 1.0 / (2 * np.pi * max(min(filt), 1e-12))
        if any(c == "mixed" for c in cls):
            tc = max(tc, 2 ** self.wavelet_level / fs / (2 * np.pi))
        return float(tc)

    def _fit_native(self, record: Record) -> "VMDWFLPCSSVR":
        """Decompose the training rate error and fit the CS-SVR drift model on its drift modes.

        Parameters
        ----------
        record : Record
            Training record (even steps; ``rate_true_dps`` used where known).

        Returns
        -------
        VMDWFLPCSSVR
            ``self`` with ``svr_`` (None when the training record has no drift mode),
            ``C_``, ``sigma_`` and ``fit_diagnostics_``.
        """
        fs = self._check(record)
        _, cls, groups, diag = self._decompose(rate_error(record), fs)
        self.svr_, self.C_, self.sigma_ = None, None, None
        diag.update({"method": self.method_name, "fs_Hz": fs, "n_samples": len(record)})
        self.input_cols_ = (0, 1)
        if np.any(cls == DRIFT):
            # inputs chosen by forward-chained validation of the linear temperature models on the
            # drift modes: dT/dt enters the SVR only when it improves their forecast
            sel = TemperatureModel(dtdt_smoothing_s=(None, self.smooth_s)).fit(
                record.time_s, record["temperature_C"], groups[DRIFT])
            self.input_cols_ = (0,) if sel.span_ is None else (0, 1)
            rep = sel.selection_.report()
            diag["selection"] = {**rep, "chosen": "CS-SVR on " + " and ".join(INPUT_NAMES[c] for c in self.input_cols_),
                                 "chosen_settings": {"inputs": [INPUT_NAMES[c] for c in self.input_cols_],
                                                     "continuation": "tangent"},
                                 "linear_model_chosen": rep["chosen"],
                                 "note": "the linear temperature models' selection on the drift modes decides "
                                         "whether dT/dt enters the CS-SVR; C and sigma are the cuckoo search's"}
            self.svr_ = CSSVR(search=self.search, budget=self.budget, n_nests=self.n_nests,
                              n_max=self.n_max, seed=self.seed, progress=self.progress).fit(
                self._features(record), groups[DRIFT])
            self.C_, self.sigma_ = self.svr_.C_, self.svr_.sigma_
            diag["cssvr"] = {"C": self.C_, "sigma": self.sigma_, "cv_rmse_dps": self.svr_.cv_rmse_,
                             "search": self.search, "nfev": self.svr_.search_result_.nfev,
                             "budget": self.budget, "epsilon_dps": self.svr_.epsilon_,
                             "inputs": [INPUT_NAMES[c] for c in self.input_cols_], "n_points": self.svr_.n_points_,
                             "beyond_training_range": "continued along the tangent plane at the edge of the "
                                                      "training box"}
        else:
            diag["cssvr"] = "not fitted: the training decomposition has no drift mode"
        self.fit_diagnostics_ = diag
        return self

    def _transform_native(self, record: Record) -> np.ndarray:
        """Compensated rate in deg/s at the record's own rate (no decimation).

        Parameters
        ----------
        record : Record
            Record to compensate (even steps).

        Returns
        -------
        ndarray
            Denoised mixed modes + drift modes minus the CS-SVR drift + the residual per
            ``residual``; ``transform_diagnostics_`` describes what was done.
        """
        fs = self._check(record)
        res, cls, groups, diag = self._decompose(np.asarray(record["rate_dps"], dtype=float), fs)
        kw = dict(wavelet=self.wavelet, level=self.wavelet_level, order=self.flp_order)
        mixed = wflp(groups[MIXED], **kw) if np.any(cls == MIXED) else groups[MIXED]
        drift = groups[DRIFT]
        subtracted = bool(np.any(cls == DRIFT) and self.svr_ is not None)
        self._drift_pred_ = None
        if subtracted:
            X = self._features(record)
            self._drift_pred_ = self.svr_.predict(X)
            drift = drift - self._drift_pred_
            names = [INPUT_NAMES[c] for c in self.input_cols_]
            v = box_extrapolation(names, X, self.svr_.lo_, self.svr_.hi_,
                                  units={"temperature_C": "degC", "dTdt_C_per_min": "K/min"})
            out = [n for n in names if v[n]["below"] > 0 or v[n]["above"] > 0]
            diag["extrapolation"] = {"variables": v, "terms_extrapolated": out, "any": bool(out),
                                     "terms_continued_linearly": out}
        residual = {"keep": res.residual, "drop": np.zeros_like(res.residual),
                    "wflp": wflp(res.residual, **kw)}[self.residual]
        diag.update({"residual_policy": self.residual, "drift_model_subtracted": subtracted,
                     "n_modes": {CLASS_NAMES[c]: int(np.sum(cls == c)) for c in (NOISE, MIXED, DRIFT)}})
        if np.any(cls == DRIFT) and self.svr_ is None:
            diag["warning"] = "drift modes found but no drift model (training record had none): kept as they are"
        self.transform_diagnostics_ = diag
        return mixed + drift + residual
