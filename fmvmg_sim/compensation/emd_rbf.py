"""Paper 000's pipeline: ``emd-rbf``, ``emd-rbf-ga`` and ``emd-rbf-ga-kf`` (section 3.3, Figure 8).

rate -> EMD -> sample entropy per IMF -> monotone noise / mixed / drift groups;
noise group dropped; mixed group denoised by an RBF network on a symmetric time-delay
embedding (hyper-parameters GA-tuned on a time-split validation for ``-ga``) [then a
scalar random-walk Kalman filter for ``-kf``]; drift group (IMFs + residue) minus an OLS
model on the temperature trend's [dT, dT^2, dT/dt]; output = denoised mixed + compensated drift.

``fit(train)`` learns the drift model and the KF noise levels (from the training error
rate_dps - rate_true_dps); ``transform(record)`` decomposes the record, fits the RBF denoiser
on its mixed group (self-supervised time split; ``denoiser_fit="train"`` learns it in ``fit``
instead) and applies the drift model. Everything the method drops, decimates or subsamples is in
``fit_diagnostics_`` / ``transform_diagnostics_``. Needs even sampling (EMD); refuses gaps.
"""

from __future__ import annotations

import numpy as np
from sklearn.utils.validation import check_is_fitted
from tqdm import tqdm

from ..record import Record
from . import sampen
from .base import Compensator, register
from .emd import emd_decompose, trend
from .ga import ga_budget, genetic_minimize
from ..analysis.allan import allan_deviation
from .kalman import ScalarKalman, cutoff_Hz, noise_variances
from .poly import check_record, rate_error
from .thermal_model import TemperatureModel
from .rbf import RBFNetwork, delay_embed, gaussian_design, ridge_weights

#: Fewest samples the pipeline accepts (EMD, 20k-sample entropy segments, 60/20/20 split).
MIN_PIPELINE_SAMPLES = 2000
#: GA genes: log10 sigma, M (integer), log10 alpha (compensation.md section 5).
GA_BOUNDS = ((-2.0, 1.0), (5, 50), (-8.0, -2.0))


def _mse(a, b):
    return float(np.mean((a - b) ** 2))


@register("emd-rbf")
class EMDRBF(Compensator):
    """EMD + sample-entropy grouping + RBF denoising of the mixed group + temperature-trend drift model.

    Parameters
    ----------
    noise_se_min, drift_se_max : float
        Sample-entropy thresholds of the groups (calibrated defaults, see :mod:`.sampen`).
    delay : int
        Time-delay embedding depth d (2d inputs).
    n_centers : int
        Hidden units M (``emd-rbf``; the GA chooses it for ``-ga``).
    sigma : float, optional
        Gaussian spread in standardised input units (default: the d_max / sqrt(2M) heuristic).
    alpha : float
        Ridge penalty per sample.
    max_train_rows : int
        The RBF output layer is fitted on at most this many rows of the training split.
    ga_rows : int
        Rows of the training and validation splits each fitness evaluation uses.
    ga_population, ga_generations : int
        GA size (budget ``ga_budget(...)`` evaluations).
    trend_min_period_s : float
        Temperature IMFs with a longer mean period join the temperature trend.
    kf_accel_rms_dps2 : float, optional
        For ``-kf``: Q from this angular acceleration instead of the Allan K (dynamic use).
    denoiser_fit : {"record", "train"}
        Where the RBF denoiser (and its GA) is fitted: on the mixed group of the record being
        compensated (self-supervised, no truth used; default, as the paper denoises the output
        it is given) or once on the training record. Measured on synthetic 2 h / 10 Hz runs,
        both give the same static-run numbers, and both flatten a dynamic run's true rate
        (truth RMS 0.94 vs 0.09 deg/s raw): the noise group takes the 2-15 Hz content, and the
        60 % training split of a non-stationary record need not contain its largest motions.
    seed : int
        Seed of subsampling, KMeans and the GA.
    progress : bool
        Show tqdm progress bars on stderr.
    """

    use_ga = False
    use_kf = False

    def __init__(self, noise_se_min=sampen.NOISE_SE_MIN, drift_se_max=sampen.DRIFT_SE_MAX, delay=4,
                 n_centers=20, sigma=None, alpha=1e-6, max_train_rows=100_000, ga_rows=10_000,
                 ga_population=30, ga_generations=40, trend_min_period_s=300.0, kf_accel_rms_dps2=None,
                 denoiser_fit="record", seed=0, progress=False):
        self.noise_se_min, self.drift_se_max, self.delay = noise_se_min, drift_se_max, delay
        self.n_centers, self.sigma, self.alpha = n_centers, sigma, alpha
        self.max_train_rows, self.ga_rows = max_train_rows, ga_rows
        self.ga_population, self.ga_generations = ga_population, ga_generations
        self.trend_min_period_s, self.kf_accel_rms_dps2 = trend_min_period_s, kf_accel_rms_dps2
        self.denoiser_fit, self.seed, self.progress = denoiser_fit, seed, progress

    # -- shared stages -------------------------------------------------------------------
    def _decompose(self, t_s, y, fs):
        res = emd_decompose(y, fs, name="rate_dps")
        ent, nseg = [], 1
        for c in tqdm(res.imfs, desc="sample entropy", disable=not self.progress, leave=False):
            v, nseg = sampen.sample_entropy(c)
            ent.append(v)
        cls = sampen.classify(np.array(ent), self.noise_se_min, self.drift_se_max)
        groups = {name: res.imfs[cls == k].sum(0) if np.any(cls == k) else np.zeros_like(y)
                  for k, name in enumerate(sampen.CLASS_NAMES)}
        groups["drift"] = groups["drift"] + res.residue
        var = np.var(y) or 1.0
        diag = {"emd_library": "emd (sift, defaults)", "n_imfs": res.n_imfs, "sample_entropy": ent,
                "se_segments_per_imf": nseg, "classes": [sampen.CLASS_NAMES[k] for k in cls] + ["drift (residue)"],
                "mean_period_s": res.mean_periods_s().tolist(),
                "dropped_noise_variance_fraction": float(np.var(groups["noise"]) / var)}
        return groups, diag

    def _trend(self, record, fs):
        return trend(record.time_s, record["temperature_C"], fs, self.trend_min_period_s)

    # -- RBF ------------------------------------------------------------------------------
    def _fit_rbf(self, x):
        """(network, mean, sd, diagnostics) of an RBF denoiser fitted on the mixed group ``x``."""
        rng = np.random.default_rng(self.seed)
        mu, sd = float(np.mean(x)), float(np.std(x)) or 1.0
        X, y = delay_embed((x - mu) / sd, self.delay)
        n = len(y)
        tr, va, te = np.arange(0, int(0.6 * n)), np.arange(int(0.6 * n), int(0.8 * n)), np.arange(int(0.8 * n), n)
        sub = lambda idx, k: np.sort(rng.choice(idx, k, replace=False)) if len(idx) > k else idx  # noqa: E731
        diag = {"delay": self.delay, "split": "60/20/20 by time", "train_rows": len(tr)}
        M, sigma, alpha = self.n_centers, self.sigma, self.alpha
        if self.use_ga:
            itr, iva = sub(tr, self.ga_rows), sub(va, self.ga_rows)
            base = RBFNetwork(random_state=self.seed)
            cache = {}

            def fitness(g):
                m = int(g[1])
                if m not in cache:
                    cache[m] = base.set_params(n_centers=m).kmeans_centers(X[itr])
                w, b = ridge_weights(gaussian_design(X[itr], cache[m], 10 ** g[0]), y[itr], 10 ** g[2])
                return _mse(gaussian_design(X[iva], cache[m], 10 ** g[0]) @ w + b, y[iva])

            bar = tqdm(total=self.ga_generations, desc="GA", disable=not self.progress, leave=False)
            res = genetic_minimize(fitness, GA_BOUNDS, integer=(False, True, False), pop_size=self.ga_population,
                                   n_generations=self.ga_generations, seed=self.seed,
                                   callback=lambda g, f: bar.update(1))
            bar.close()
            sigma, M, alpha = 10 ** res.x[0], int(res.x[1]), 10 ** res.x[2]
            diag["ga"] = {"n_evals": res.n_evals, "budget": ga_budget(self.ga_population, self.ga_generations),
                          "best_val_mse_norm": res.fun, "rows_per_eval": [len(itr), len(iva)],
                          "history": res.history}
        itrain = sub(tr, self.max_train_rows)
        net = RBFNetwork(int(M), sigma, alpha, random_state=self.seed).fit(X[itrain], y[itrain])
        iva, ite = sub(va, self.max_train_rows), sub(te, self.max_train_rows)
        diag.update({"n_centers": int(M), "sigma": net.sigma_, "alpha": float(alpha),
                     "fit_rows": len(itrain), "kmeans_rows": min(len(itrain), net.max_kmeans_samples),
                     "val_mse_norm": _mse(net.predict(X[iva]), y[iva]),
                     "test_mse_norm": _mse(net.predict(X[ite]), y[ite]),
                     "note": "mse_norm: MSE of the standardised mixed group; 1.0 = no better than its mean"})
        return net, mu, sd, diag

    def _apply_rbf(self, x, den):
        net, mu, sd = den
        X, _ = delay_embed((x - mu) / sd, self.delay)
        return net.predict(X) * sd + mu

    def _filter_time_constant(self, diag: dict, fs: float) -> tuple[float, str]:
        """Longest time constant of what the pipeline drops or filters, in s, and where it comes from.

        1 / (2 pi f_c) of the Kalman filter, (mean period) / (2 pi) of the longest dropped noise
        IMF, and the RBF's embedding window (2 d + 1) / fs; the Allan bias instability is only
        worth reading at tau well above it.
        """
        tcs = {}
        noise = [p for p, c in zip(diag.get("mean_period_s") or [], diag.get("classes") or [])
                 if c == "noise" and np.isfinite(p)]
        if noise:
            tcs["dropped noise IMFs"] = max(noise) / (2 * np.pi)
        if diag.get("rbf_applied"):
            tcs["RBF embedding"] = (2 * self.delay + 1) / fs / (2 * np.pi)
        kf = getattr(self, "fit_diagnostics_", {}).get("kf") if self.use_kf else None
        if kf and kf.get("cutoff_Hz"):
            tcs["Kalman filter"] = 1.0 / (2 * np.pi * float(kf["cutoff_Hz"]))
        if not tcs:
            return 0.0, "nothing dropped or filtered"
        k = max(tcs, key=tcs.get)
        return float(tcs[k]), f"{k} ({', '.join(f'{n} {v:.3g} s' for n, v in tcs.items())})"

    # -- estimator API ----------------------------------------------------------------------
    def _check(self, record):
        if self.denoiser_fit not in ("record", "train"):
            raise ValueError(f"denoiser_fit must be 'record' or 'train', got {self.denoiser_fit!r}")
        check_record(record, need_uniform=True, min_samples=MIN_PIPELINE_SAMPLES, method=self.method_name)
        return 1.0 / record.sample_interval_s()

    def fit(self, record: Record, _decomp=None) -> "EMDRBF":
        """Learn the drift model, RBF network (and KF noise) from a training record.

        Parameters
        ----------
        record : Record
            Training record (even steps; ``rate_true_dps`` used where known).

        Returns
        -------
        EMDRBF
            ``self``, with ``fit_diagnostics_``.
        """
        fs = self._check(record)
        groups, diag = _decomp or self._decompose(record.time_s, rate_error(record), fs)
        tr, tinfo = self._trend(record, fs)
        self.drift_model_ = TemperatureModel(presmoothed=True).fit(record.time_s, tr, groups["drift"])
        self.T_ref_C_ = self.drift_model_.T_ref_C_
        diag.update({"method": self.method_name, "fs_Hz": fs, "n_samples": len(record), "temperature_trend": tinfo,
                     "drift_model": {**self.drift_model_.report(), "fit_rate_Hz": 1.0,
                                     "target": "the drift group (drift IMFs + residue)"}})
        self.denoiser_ = None
        if self.denoiser_fit == "train" and np.any(groups["mixed"]):
            *self.denoiser_, diag["rbf"] = self._fit_rbf(groups["mixed"])
        if self.use_kf:
            a, notes = allan_deviation(record["rate_dps"], fs), []
            n_arw, k_rrw = a.N, a.K
            if n_arw is None:  # no -1/2 region: the shortest-tau reading (an upper bound)
                n_arw = float(a.adev[0] * np.sqrt(a.taus_s[0]))
                notes.append("no -1/2 Allan region: R from the shortest tau")
            if k_rrw is None and self.kf_accel_rms_dps2 is None:  # no +1/2 region: bound from the longest tau
                use = np.flatnonzero(a.n_clusters >= a.min_clusters)[-1]
                k_rrw = float(a.adev[use] * np.sqrt(3.0 / a.taus_s[use]))
                notes.append(f"no +1/2 Allan region: K bounded at tau = {a.taus_s[use]:g} s")
            self.kf_q_, self.kf_r_ = noise_variances(n_arw, k_rrw, fs, self.kf_accel_rms_dps2)
            k = ScalarKalman(self.kf_q_, self.kf_r_).steady_gain
            diag["kf"] = {"q": self.kf_q_, "r": self.kf_r_, "arw_dps_per_rtHz": n_arw, "rrw_dps_per_rts": k_rrw,
                          "steady_gain": k, "cutoff_Hz": cutoff_Hz(k, fs),
                          "q_source": "accel_rms" if self.kf_accel_rms_dps2 is not None else "allan K",
                          "notes": notes}
        self.fit_diagnostics_ = diag
        return self

    def compensate_rate_dps(self, record: Record, _decomp=None) -> np.ndarray:
        """Compensated rate in deg/s (noise group dropped, mixed denoised, drift compensated).

        Parameters
        ----------
        record : Record
            Record to compensate (even steps).

        Returns
        -------
        ndarray
        """
        check_is_fitted(self, "drift_model_")
        fs = self._check(record)
        groups, diag = _decomp or self._decompose(record.time_s, record["rate_dps"], fs)
        mixed, den = groups["mixed"], self.denoiser_
        if self.denoiser_fit == "record" and np.any(mixed):
            *den, diag["rbf"] = self._fit_rbf(mixed)
        if den is not None:
            mixed = self._apply_rbf(mixed, den)
        if self.use_kf:
            mixed = ScalarKalman(self.kf_q_, self.kf_r_).filter(mixed)
        tr, tinfo = self._trend(record, fs)
        drift = groups["drift"] - self.drift_model_.predict(record.time_s, tr)
        diag.update({"temperature_trend": tinfo, "kf_applied": self.use_kf, "rbf_applied": den is not None,
                     "rbf_fitted_on": self.denoiser_fit,
                     "extrapolation": self.drift_model_.extrapolation(record.time_s, tr)})
        diag["filter_time_constant_s"], diag["filter_time_constant_source"] = self._filter_time_constant(diag, fs)
        self.transform_diagnostics_ = diag
        return mixed + drift

    def _fit_compensate_rate_dps(self, record: Record) -> np.ndarray:
        """Fit and compensate the same record (in-sample); decomposes once when no truth is known.

        Parameters
        ----------
        record : Record
            Record to fit on and compensate.

        Returns
        -------
        ndarray
        """
        fs = self._check(record)
        e = rate_error(record)
        dec = self._decompose(record.time_s, e, fs) if np.array_equal(e, record["rate_dps"]) else None
        self.fit(record, _decomp=None if dec is None else (dec[0], dict(dec[1])))
        return self.compensate_rate_dps(record, _decomp=None if dec is None else (dec[0], dict(dec[1])))


@register("emd-rbf-ga")
class EMDRBFGA(EMDRBF):
    """``emd-rbf`` with (sigma, M, alpha) tuned by the GA on the time-split validation MSE."""

    use_ga = True


@register("emd-rbf-ga-kf")
class EMDRBFGAKF(EMDRBF):
    """``emd-rbf-ga`` followed by the scalar random-walk Kalman filter on the denoised mixed group."""

    use_ga = True
    use_kf = True
