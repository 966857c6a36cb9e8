"""Forward-chained held-out scoring: each model refitted on a fold's training blocks and judged on its test blocks.

The record's blocks are split into forward-chained folds (:meth:`~.data.Prepared.folds`): each fold trains on
everything before a gap and is tested on the segment after it. A model (the calibrated nominal model, or the
nominal model with one or two library effects) is refitted on each fold's training blocks and predicts the
fold's test blocks; its held-out score is the negative log-likelihood of those blocks under the null's noise
model (:mod:`.likelihood`), each block's prediction carrying its own uncertainty (the refit's parameter
covariance through the model's sensitivities). A prediction the training window does not determine (a scale
factor with no applied rate to learn it from, a temperature law on a window at one temperature) is thereby
scored as uncertain rather than as one arbitrary point of its uncertainty.

:class:`Scorer` holds the folds, the baseline predictions and the noise model, and computes a candidate's
held-out gain over a baseline (:class:`HeldOutGain`) and its held-out gap shrink (:meth:`Scorer.shrink`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .calibrate import Calibration
from .fitting import Fitter
from .forward import CHANNELS
from .likelihood import block_bootstrap_ci, expected_gain, fit_params, nll, nll_by_channel
from .model import EffectModel

#: Folds whose passing alone carries a candidate.
FOLDS_NEEDED = 2
#: A fold passes when its held-out log-likelihood gain (summed over its blocks) is at least this (odds of
#: 20:1) with a bootstrap interval above zero: a smooth candidate that differs from the baseline by a
#: hair has a "significant" but worthless gain of a fraction of a nat.
FOLD_MIN_NATS = 3.0
#: Expected held-out gain (nats) of a candidate over its baseline, were the candidate true, below which a fold
#: cannot test it: with ``I`` nats expected the gain scatters by about ``sqrt(2 I)``, so a fold expecting
#: fewer than 10 nats fails a true effect's interval test about as often as it passes it.
FOLD_INFO_NATS = 10.0
#: Relative model accuracy allowed when checking a fold's gain against the gain expected were the candidate
#: true (beside the noise scatter ``3 sqrt(2 I)``); see :meth:`Scorer.folds_ok`.
FOLD_CONSISTENCY_REL = 0.25
#: The testable folds' summed gain, in standard deviations ``sqrt(2 sum I)`` of its scatter, that passes a
#: candidate that too few folds pass one by one (:meth:`Scorer.folds_ok`).
FOLDS_COMBINED_Z = 2.0
#: Expected held-out gain (nats), were the candidate true, from which a fold joins the combined fold test
#: although too little of the candidate is in it to test it alone: a true candidate's gain there is positive
#: with probability Phi(sqrt(I / 2)), 0.94 at 5 nats.
FOLD_JOIN_NATS = 5.0
#: Temperature span (K) a fold's training window needs to be scored: a window at one temperature does not
#: determine a temperature law, and its test would score an arbitrary extrapolation.
MIN_TRAIN_SPAN_K = 5.0

#: The headline gap: held-out excess mean square over the null's, in units of the null's (at least
#: :data:`GAP_UNIT_Z2`), summed over channels.
TOTAL_GAP = "total_excess_over_noise"
#: The least unit of a channel's held-out gap, in squared held-out sigmas. A channel whose sigma is a model floor or
#: the laws' stated accuracy (the drive frequency, a law extrapolated beyond the training temperatures) has null
#: replicates far inside it (mean square 1e-5 of it): in the null's units, a misfit a hundredth of that sigma would
#: read as a gap of tens and outweigh a rate channel whose gap is many sigmas. One sigma squared is what the channel
#: states it can resolve.
GAP_UNIT_Z2 = 1.0


@dataclass
class FoldScore:
    """One fold's held-out gain of a candidate over its baseline.

    Attributes
    ----------
    gain : float
        Mean gain per held-out block (nats).
    ci : list of float
        Its block-bootstrap 95 % interval.
    total : float
        Summed gain (nats).
    info_if_true : float
        The gain expected were the candidate true (the Kullback-Leibler divergence of the two predictions).
    consistent : bool
        ``total`` lies within the scatter of ``info_if_true`` (:data:`FOLD_CONSISTENCY_REL` beside it).
    """

    gain: float
    ci: list
    total: float
    info_if_true: float
    consistent: bool

    @property
    def testable(self) -> bool:
        """The fold carries enough of the candidate to test it alone (:data:`FOLD_INFO_NATS`)."""
        return bool(self.info_if_true >= FOLD_INFO_NATS)

    @property
    def passed(self) -> bool:
        """Its interval lies above zero and its summed gain reaches :data:`FOLD_MIN_NATS`."""
        return bool(self.ci[0] > 0 and self.total >= FOLD_MIN_NATS)


@dataclass
class HeldOutGain:
    """A candidate's held-out gain over its baseline, pooled over the folds.

    Attributes
    ----------
    gain : float
        Mean gain per held-out block (nats); ``-inf`` for a model that could not be fitted.
    ci : list of float
        Block-bootstrap 95 % interval of the pooled gain.
    folds : list of FoldScore
    by_channel : dict
        Mean gain per block of each channel.
    folds_ok : bool
        Whether the folds carry the candidate (:meth:`Scorer.folds_ok`).
    """

    gain: float
    ci: list
    folds: list = field(default_factory=list)
    by_channel: dict = field(default_factory=dict)
    folds_ok: bool = False

    @property
    def folds_passed(self) -> int:
        """Folds that pass on their own."""
        return int(sum(f.passed for f in self.folds))

    @property
    def folds_testable(self) -> int:
        """Folds that carry enough of the candidate to test it alone."""
        return int(sum(f.testable for f in self.folds))

    @classmethod
    def failed(cls) -> "HeldOutGain":
        """The score of a model that could not be fitted.

        Returns
        -------
        HeldOutGain
        """
        return cls(-np.inf, [-np.inf, -np.inf])

    def to_json(self) -> dict:
        """JSON form.

        Returns
        -------
        dict
        """
        return {"gain": self.gain, "ci": list(self.ci), "folds_passed": self.folds_passed,
                "folds_testable": self.folds_testable, "by_channel": dict(self.by_channel),
                "folds": [{"gain": f.gain, "ci": list(f.ci), "total": f.total, "info_if_true": f.info_if_true,
                           "testable": f.testable, "passed": f.passed, "consistent": f.consistent}
                          for f in self.folds]}


class Scorer:
    """Forward-chained held-out scoring of model fits against a baseline.

    Parameters
    ----------
    fitter : Fitter
    cal : Calibration
    noise_params : list of tuple, optional
        Slow-state noise model ``(rho, K, s)`` of each channel's block residual normalised by the scoring sigma
        (:meth:`~.fitting.Fitter.residual` with ``scoring=True``), from the null replicates; without it each
        model's own training residual sets it (a smooth misfit then looks cheap).
    noise_ms : dict, optional
        The null's held-out mean square per metric (:meth:`metrics`): the noise level the held-out gaps are
        read above.
    """

    def __init__(self, fitter: Fitter, cal: Calibration, noise_params: list | None = None,
                 noise_ms: dict | None = None):
        self.f = fitter
        self.cal = cal
        self.noise_params = noise_params
        self.noise_ms = noise_ms or {}
        folds = fitter.prep.folds()
        self.train = folds[-1]["train"]
        T = fitter.prep.block_mean(fitter.prep.case_C)
        span = [float(np.nanmax(T[fd["train"]]) - np.nanmin(T[fd["train"]])) if fd["train"].any() else 0.0
                for fd in folds]
        keep = [k for k, sp in enumerate(span) if sp >= MIN_TRAIN_SPAN_K and folds[k]["test"].any()]
        #: the folds scored (those whose training window leaves one temperature; all of them when none does)
        self.folds = [folds[k] for k in keep] if keep else folds
        self.dropped_folds = [k for k in range(len(folds)) if k not in keep] if keep else []
        self.folds_needed = min(FOLDS_NEEDED, len(self.folds))
        #: every held-out block, and its sigma (noise and the laws' accuracy there)
        self.heldout = heldout_blocks(fitter.prep)
        self.S_heldout = heldout_sigma(fitter)
        # the nominal model fitted as every candidate is (the same steps from the calibration, no effect), so that a
        # candidate gains only what its effect explains, not the steps the calibration left to take
        self.nominal_fit = EffectModel(fitter, cal, []).fit(self.train)
        self.nominal = self.fold_predictions(self.nominal_fit.refit)
        self.nominal_train_pred = self.nominal_fit._ctx["pred"]

    def fold_predictions(self, refit) -> dict:
        """Predictions of ``refit(rows)`` on each fold, with their uncertainty, plus the stitched held-out prediction.

        Parameters
        ----------
        refit : callable
            ``rows -> (pred, effects, (lin, cov))``: the prediction of a fit on ``rows``, the fitted effects, the
            fit's linearisation and its parameter covariance.

        Returns
        -------
        dict
            ``folds``: list of ``(pred, effects, sd)``, ``sd`` the prediction's sd on the fold's test blocks;
            ``heldout``: stitched block prediction (NaN outside the tests).
        """
        out, ho = [], np.full_like(self.f.Y, np.nan)
        for fd in self.folds:
            pred, eff, (lin, cov) = refit(fd["train"])
            sd = lin.predict_sd(cov, fd["test"])
            out.append((pred, eff, sd))
            ho[fd["test"]] = pred[fd["test"]]
        return {"folds": out, "heldout": ho}

    def channel_noise(self, base_pred: np.ndarray, rows: np.ndarray) -> list:
        """Noise model of each channel for scoring candidates against ``base_pred``.

        Parameters
        ----------
        base_pred : ndarray, shape (n, C)
            The baseline's prediction (fitted on ``rows``).
        rows : ndarray of bool
            Training blocks.

        Returns
        -------
        list of tuple or None
        """
        return self.noise_params or fit_params(self.f.residual(base_pred, scoring=True)[rows])

    def _heldout_nll(self, fold: tuple, rows: np.ndarray, par: list, law_sd: np.ndarray) -> np.ndarray:
        """Per-block, per-channel held-out NLL of one fold's prediction, its own uncertainty included.

        Each block's predictive sd is ``sqrt(S^2 + sd^2 + law^2)`` (``S`` the scoring sigma, ``sd`` the prediction's
        own, ``law`` the laws' accuracy beyond the fold's training temperatures): the residual is scaled by it and
        the density carries its log.
        """
        pred, _, sd = fold
        scale = np.sqrt(1.0 + (np.nan_to_num(sd) ** 2 + law_sd ** 2) / self.f.S_score[rows] ** 2)
        Z = self.f.residual(pred, scoring=True)[rows] / scale
        out = nll_by_channel(Z, par) + np.where(np.isfinite(Z), np.log(scale), 0.0)
        if self.f.converter:
            # channels read through a coarse converter: the prediction through its staircase instead
            mom = self.f.converter_moments(pred, rows, sd)
            conv = self.f.converter_nll(mom, rows)
            for c in self.f.converter:
                out[:, c] = conv[:, c]
        return out

    def gain(self, cand: dict, base: dict) -> HeldOutGain:
        """Held-out NLL gain per block of ``cand`` over ``base`` (both from :meth:`fold_predictions`).

        Parameters
        ----------
        cand, base : dict

        Returns
        -------
        HeldOutGain
        """
        allv, folds, by_ch = [], [], []
        for k, fd in enumerate(self.folds):
            par = self.channel_noise(base["folds"][k][0], fd["train"])
            if self.f.converter:
                par = [None if c in self.f.converter else p for c, p in enumerate(par)]
            rows = fd["test"]
            law = self.f.law_sd(fd["train"])[rows]
            dch = (self._heldout_nll(base["folds"][k], rows, par, law)
                   - self._heldout_nll(cand["folds"][k], rows, par, law))
            by_ch.append(dch)
            diff = dch.sum(axis=1)
            lo, hi = block_bootstrap_ci(diff, seed=k)
            # the gain expected were the candidate true: the Kullback-Leibler divergence between the two predictive
            # distributions on the held-out blocks (the whitened energy of the prediction change)
            dZ = ((self.f.residual(base["folds"][k][0], scoring=True)
                   - self.f.residual(cand["folds"][k][0], scoring=True))[rows]
                  / np.sqrt(1.0 + law ** 2 / self.f.S_score[rows] ** 2))
            if self.f.converter:
                dZ[:, list(self.f.converter)] = 0.0
            info = max(expected_gain(dZ, par), 0.0)
            tot = float(np.sum(diff))
            # were the candidate true, the fold's gain would scatter about ``info`` by sqrt(2 info)
            consistent = abs(tot - info) <= 3.0 * np.sqrt(2.0 * info) + FOLD_CONSISTENCY_REL * info
            folds.append(FoldScore(float(np.mean(diff)), [lo, hi], tot, info, bool(consistent)))
            allv.append(diff)
        pooled = np.concatenate(allv)
        lo, hi = block_bootstrap_ci(pooled, seed=99)
        ch = np.concatenate(by_ch).mean(axis=0)
        g = HeldOutGain(float(np.mean(pooled)), [lo, hi], folds,
                        {c: float(v) for c, v in zip(CHANNELS, ch) if self.f.present[CHANNELS.index(c)]})
        g.folds_ok = self.folds_ok(g)
        return g

    def folds_ok(self, g: HeldOutGain) -> bool:
        """Whether the folds carry the candidate: :data:`FOLDS_NEEDED` pass, the one fold that can test it passes,
        or the folds that can test it pass together.

        Where a single fold can test it (a ramp-rate term beside a record of holds), that fold carries the
        candidate when it passes and its gain is also what the candidate would earn were it true: a gain far above
        it comes from a larger misfit (slow noise, another effect) the candidate merely leans against. Where
        several folds can test it but fewer pass, all of them must gain, each as the candidate would were it true,
        and their summed gain must reach :data:`FOLDS_COMBINED_Z` standard deviations of its scatter (were the
        candidate false, the sum would centre on ``-sum(I)``). Failing these, the same combined test is asked of
        every fold carrying at least :data:`FOLD_JOIN_NATS` of the candidate.

        Parameters
        ----------
        g : HeldOutGain

        Returns
        -------
        bool
        """
        if g.folds_passed >= self.folds_needed:
            return True
        testable = [f for f in g.folds if f.testable]
        if len(testable) == 1 and testable[0].passed and testable[0].consistent:
            return True
        joined = [f for f in g.folds if f.info_if_true >= FOLD_JOIN_NATS]
        return any(together(fs) for fs in (testable, joined))

    def delta_bic(self, pred_cand: np.ndarray, pred_base: np.ndarray, k_extra: int,
                  rows: np.ndarray | None = None) -> float:
        """BIC(candidate) - BIC(base) on the training window, or on ``rows``.

        Parameters
        ----------
        pred_cand, pred_base : ndarray
        k_extra : int
        rows : ndarray of bool, optional

        Returns
        -------
        float
        """
        rows = self.train if rows is None else rows
        v = []
        for pred in (pred_cand, pred_base):
            Z = self.f.residual(pred, scoring=True)[rows]
            v.append(float(np.sum(nll(Z, self.noise_params or fit_params(Z)))))
        n = int(np.isfinite(self.f.residual(pred_base, scoring=True)[rows]).sum())
        return 2 * (v[0] - v[1]) + k_extra * np.log(max(n, 2))

    # ---- held-out gaps ------------------------------------------------------------------------
    def metrics(self, pred: np.ndarray, Y: np.ndarray | None = None) -> dict:
        """Mean-square held-out residual per metric (:func:`heldout_metrics`).

        Parameters
        ----------
        pred : ndarray, shape (n, C)
        Y : ndarray, optional
            Other observations on the same blocks (a null replicate); default the record's.

        Returns
        -------
        dict
        """
        return heldout_metrics(self.f, self.heldout, pred, Y, self.S_heldout)

    def gaps(self, pred: np.ndarray) -> dict:
        """Held-out excess mean squares over the null's, plus the located gap (:data:`TOTAL_GAP`): the excess of each
        channel's residual in its held-out sigmas (:func:`heldout_sigma`) over the null's, in units of the null's or
        of :data:`GAP_UNIT_Z2` where the null's is smaller, summed over the channels.

        Parameters
        ----------
        pred : ndarray, shape (n, C)
            A held-out prediction (NaN outside the tests).

        Returns
        -------
        dict
        """
        noise = self.noise_ms
        ms = self.metrics(pred)
        out = {k: max(0.0, v - noise.get(k, 0.0)) for k, v in ms.items() if not k.startswith("z2_")}
        # the located gap: each channel's held-out excess over the null's, in its sigmas (noise and the laws'
        # accuracy beyond the training temperatures), in units of the null's: at least one sigma squared
        out[TOTAL_GAP] = float(sum(max(0.0, v - noise[k]) / max(noise[k], GAP_UNIT_Z2) for k, v in ms.items()
                                   if k.startswith("z2_") and noise.get(k, 0.0) > 0))
        return out

    def shrink(self, pred_after: np.ndarray, pred_before: np.ndarray) -> float | None:
        """Held-out shrink of the gap ``pred_before`` leaves when ``pred_after`` replaces it: ``1 - G_after / G_before``.

        Parameters
        ----------
        pred_after, pred_before : ndarray
            Held-out predictions.

        Returns
        -------
        float or None
            None when ``pred_before`` leaves no gap above the noise.
        """
        b = self.gaps(pred_before)[TOTAL_GAP]
        return float(1.0 - self.gaps(pred_after)[TOTAL_GAP] / b) if b > 0 else None


def heldout_sigma(fitter: Fitter) -> np.ndarray:
    """Each held-out block's sigma: its noise and the laws' accuracy beyond its fold's training temperatures.

    Parameters
    ----------
    fitter : Fitter

    Returns
    -------
    ndarray, shape (n_blocks, C)
        ``sqrt(S^2 + law^2)`` on each fold's test blocks (:meth:`~.fitting.Fitter.law_sd`), ``S`` elsewhere.
    """
    out = fitter.S.copy()
    for fd in fitter.prep.folds():
        out[fd["test"]] = np.sqrt(fitter.S ** 2 + fitter.law_sd(fd["train"]) ** 2)[fd["test"]]
    return out


def heldout_metrics(fitter: Fitter, mask: np.ndarray, pred: np.ndarray, Y: np.ndarray | None = None,
                    S: np.ndarray | None = None) -> dict:
    """Mean-square residual per metric on the blocks ``mask``: each channel, and the rate output by regime.

    Parameters
    ----------
    fitter : Fitter
    mask : ndarray of bool
        Blocks (the held-out ones).
    pred : ndarray, shape (n, C)
    Y : ndarray, optional
        Other observations on the same blocks (a null replicate); default the record's.
    S : ndarray, shape (n, C), optional
        Block sigmas (:func:`heldout_sigma`): also the mean square of each channel's residual in them.

    Returns
    -------
    dict
        ``rms_rate_dps`` (deg/s squared), ``rms_<channel>``, ``rms_rate_dps_<regime>``, and with ``S``
        ``z2_<channel>``.
    """
    prep = fitter.prep
    R = (fitter.Y if Y is None else Y) - pred
    sf = prep.sf_nominal_V_per_dps
    out = {}
    for i, c in enumerate(CHANNELS):
        if c not in prep.channels:
            continue
        k = "rms_rate_dps" if c == "rate_V" else f"rms_{c}"
        out[k] = float(np.nanmean((R[mask, i] / (sf if c == "rate_V" else 1.0)) ** 2))
        if S is not None:
            out[f"z2_{c}"] = float(np.nanmean((R[mask, i] / S[mask, i]) ** 2))
    for r in ("hold", "heating", "cooling"):
        m = mask & prep.block_regime(r)
        if m.sum() >= 3:
            out[f"rms_rate_dps_{r}"] = float(np.nanmean((R[m, 0] / sf) ** 2))
    return out


def heldout_blocks(prep) -> np.ndarray:
    """Every block some fold holds out.

    Parameters
    ----------
    prep : Prepared

    Returns
    -------
    ndarray of bool
    """
    out = np.zeros(prep.n_blocks, bool)
    for fd in prep.folds():
        out |= fd["test"]
    return out


def together(folds: list) -> bool:
    """Whether ``folds`` (two or more) carry a candidate together: each gains, consistent with the gain expected
    were the candidate true, and the summed gain stands :data:`FOLDS_COMBINED_Z` scatters above zero.

    Parameters
    ----------
    folds : list of FoldScore

    Returns
    -------
    bool
    """
    if len(folds) < 2 or not all(f.consistent and f.total > 0 for f in folds):
        return False
    total = sum(f.total for f in folds)
    info = sum(f.info_if_true for f in folds)
    return bool(total >= FOLDS_COMBINED_Z * np.sqrt(2.0 * info))
