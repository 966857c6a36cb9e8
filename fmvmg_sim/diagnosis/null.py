"""The null: the calibrated nominal model re-simulated with its noise on the record's own inputs.

A few replicates of the calibrated unit (its knobs drawn from the calibration's posterior) are simulated with
the envelope engine on the record's temperature and applied rate (:func:`.localize.null_records`), read through
the record's converter and the calibrated channel knobs, and given the auxiliary-channel noise the record
carries beyond the simulated loop's (:mod:`.noise_match`); beyond the training temperatures their localisation
statistics also hold the laws' error at its stated accuracy (:func:`law_errors`). Every statistic of the diagnosis is read on them as on
the record: the localisation's null band, the scoring noise model, the held-out noise level, the flicker band,
the record-design note.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import localize as loc
from .calibrate import Calibration
from .converter import Converter, lattice_noise, staircase_visible
from .data import CONVERTER_CHANNELS, ON_LATTICE_MIN, Prepared, difference_sigma, lattice_lsb
from .fitting import Fitter
from .forward import CHANNELS, IRATE
from .heldout import heldout_blocks, heldout_metrics, heldout_sigma
from .likelihood import innovations, slow_state_fit
from .noise_match import matched_noise
from .windows import window_masks, window_stats

#: Null re-simulations (each a full envelope run on the record's inputs).
N_NULL = 6
#: Floor on the white part of a channel's scoring noise model (in scoring sigmas).
NOISE_SD_FLOOR = 0.05


@dataclass
class Null:
    """The null replicates and what the diagnosis reads off them.

    Attributes
    ----------
    thetas : list of dict
        Each replicate's knobs.
    records : list of dict
        Each replicate's channels at the record's sample times.
    preds : list of ndarray
        Each replicate's noise-free block prediction (its own knobs).
    blocks : list of ndarray
        Each replicate's block means (matched auxiliary noise included).
    stats : list of dict
        Each replicate's localisation statistics (:func:`.localize.residual_stats`) against its own calibration.
    windows : list of dict
        Each replicate's record-design window statistics (:func:`.windows.window_stats`).
    noise_params : list
        Slow-state noise model per channel of the scoring residual, pooled over the replicates.
    noise_ms : dict
        Mean held-out squared residual per metric of the noise alone (:func:`.heldout.heldout_metrics`).
    allan_heldout, allan_train : list of ndarray
        Each replicate's rate-residual Allan deviation on the held-out and training samples.
    converter : dict
        The record's coarse converter by channel index (:func:`converter_model`).
    """

    thetas: list
    records: list
    preds: list
    blocks: list
    stats: list
    windows: list
    noise_params: list
    noise_ms: dict
    allan_heldout: list
    allan_train: list
    converter: dict


def posterior_draws(cal: Calibration, n: int, seed: int) -> list[dict]:
    """Nominal knobs drawn from the calibration's Laplace posterior, inside the calibration bounds.

    Each null replicate is re-calibrated on its own data, so the estimation error the record's residual carries
    arises in the replicate itself; the draws only spread the units the way the posterior allows (a knob the
    prior, not the data, holds keeps its spread after the refit).

    Parameters
    ----------
    cal : Calibration
    n, seed : int

    Returns
    -------
    list of dict
    """
    lin = cal.lin
    x0 = np.asarray(cal.solution.x, float)
    C = np.asarray(cal.solution.cov, float)
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    L = V * np.sqrt(np.clip(w, 0.0, None))
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x6E756C6C]))
    return [dict(zip(lin.names, map(float, np.clip(x0 + L @ rng.standard_normal(len(x0)), lin.lo, lin.hi))))
            for _ in range(n)]


def law_errors(fitter: Fitter, train: np.ndarray, n: int, seed: int) -> list[np.ndarray]:
    """Each replicate's error of the model's laws beyond the training temperatures, drawn at their stated accuracy.

    The record's residual beyond the temperatures the calibration saw holds the nominal laws' own error there (a law
    of another form, fitted over the window, extrapolates off by up to :data:`fmvmg_sim.uncertainty.LAW_CURVATURE`
    times the squared distance of the channel's value); the replicates, simulated with the model's laws, hold none.
    The localisation reads both against the same accuracy (:meth:`.fitting.Fitter.law_sd`), so the replicates carry
    an error of that size: on each channel the law-accuracy curve with a normal amplitude, one per replicate. Zero
    inside the training temperatures and for a device that states no law accuracy.

    Parameters
    ----------
    fitter : Fitter
        After :meth:`~.fitting.Fitter.set_law_accuracy`.
    train : ndarray of bool
        The calibration's training blocks.
    n, seed : int

    Returns
    -------
    list of ndarray, shape (n_blocks, C)
    """
    sd = np.nan_to_num(fitter.law_sd(train))
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x6C6177]))
    return [sd * rng.standard_normal(sd.shape[1]) for _ in range(n)]


def converter_model(prep: Prepared, raw_nulls: list, null_preds: list) -> dict:
    """The coarse converter of each channel whose staircase shows, from the record's lattice and the null.

    The lattice is the record's own (:meth:`~.data.Prepared.lattice`); the noise that dithers it is not (a
    quantiser much coarser than its noise hides it), so it is read off the null replicates before their lattice
    is applied: the per-sample white level from first differences (from the share of repeated levels when the
    replicate sits on the nominal converter's own lattice, :func:`~.converter.lattice_noise`), and the slow level
    from each replicate's block means about its own device's prediction.

    Parameters
    ----------
    prep : Prepared
    raw_nulls : list of dict
        Null replicates before the lattice (:func:`~.localize.null_records`).
    null_preds : list of ndarray
        Each replicate's noise-free block prediction.

    Returns
    -------
    dict
        ``{channel index: Converter}`` (empty without a visible staircase).
    """
    out = {}
    if not raw_nulls:
        return out
    L, offsets = prep.lattice(), prep.lattice_offsets()
    for c in CONVERTER_CHANNELS:
        i = CHANNELS.index(c)
        if c not in prep.channels or not L[i] > 0:
            continue
        taus, slow = [], []
        n = np.maximum(prep.block_counts(c), 1)
        for raw, pred in zip(raw_nulls, null_preds):
            x = np.asarray(raw[c], dtype=float)
            l0, on = lattice_lsb(x)
            # a replicate on the nominal converter's (finer) lattice: a robust spread of its differences would be
            # one nominal step whatever the noise
            tau = lattice_noise(x, l0) if l0 > 0 and on >= ON_LATTICE_MIN else difference_sigma(x)
            r = prep.block_mean(raw[c]) - pred[:, i]
            ok = np.isfinite(r)
            taus.append(tau)
            slow.append(np.sqrt(max(float(np.var(r[ok])) - float(np.mean(tau ** 2 / n[ok])), 0.0)) if ok.any()
                        else np.nan)
        tau, sl = float(np.nanmedian(taus)), float(np.nanmedian(slow))
        if staircase_visible(float(L[i]), tau) and np.isfinite(sl):
            out[i] = Converter(float(L[i]), tau, sl, float(offsets[i]))
    return out


def pooled_noise_model(null_Z: list) -> list:
    """Slow-state noise model ``(rho, K, s)`` per channel, pooled over the null replicates (``s`` floored).

    An AR(1) alone cannot hold both the white block noise and the slow flicker wander of the rate output, and
    then credits any candidate that follows the wander (:mod:`.likelihood`).

    Parameters
    ----------
    null_Z : list of ndarray, shape (n, C)

    Returns
    -------
    list of tuple or None
    """
    out = []
    for c in range(null_Z[0].shape[1]):
        series = [Z[:, c] for Z in null_Z if np.isfinite(Z[:, c]).sum() > 3]
        if not series:
            out.append(None)
            continue
        rho, K, s = slow_state_fit(series)
        out.append((rho, K, max(s, NOISE_SD_FLOOR)))
    return out


def accuracy_floored(params: list, Z_train: np.ndarray) -> list:
    """The null's noise model with each auxiliary channel's innovation sd floored at the record's own: what the
    calibrated model leaves on the record's training window, filtered as the null's model filters it.

    The null replicates are the nominal model's own units, so their auxiliary channels (the drive amplitude, the AGC
    effort, the drive frequency) follow its laws to the noise and their innovations sit far below the scoring sigma.
    A unit's laws and data acquisition never match the nominal ones that closely: its calibrated residual there is
    the model's accuracy, and a noise model tighter than it weighs a channel's model error as evidence. The rate
    output's noise has its own judgement (the flicker band, :func:`.pipeline.record_rate_noise`).

    Parameters
    ----------
    params : list of tuple or None
        ``(rho, K, s)`` per channel (:func:`pooled_noise_model`).
    Z_train : ndarray, shape (n, C)
        The record's scoring residual against its calibration on the training blocks.

    Returns
    -------
    list of tuple or None
    """
    out = list(params)
    for c, par in enumerate(params):
        if par is None or c == IRATE or np.isfinite(Z_train[:, c]).sum() < 10:
            continue
        rho, K, s = par
        e = innovations(Z_train[:, c], rho, K)
        out[c] = (rho, K, max(s, float(np.sqrt(np.nanmean(e[1:] ** 2)))))
    return out


def rate_residual(prep: Prepared, pred_b: np.ndarray, rate_V: np.ndarray) -> np.ndarray:
    """Full-rate residual of the rate output (deg/s) against a block prediction (interpolated in time).

    Parameters
    ----------
    prep : Prepared
    pred_b : ndarray, shape (n_blocks, C)
    rate_V : ndarray

    Returns
    -------
    ndarray
    """
    tb = prep.block_time_s()
    return (rate_V - np.interp(prep.t_mid_s, tb, pred_b[:, IRATE])) / prep.sf_nominal_V_per_dps


def simulate_null(scn, fitter: Fitter, cal: Calibration, n: int, seed: int, progress: bool = False) -> Null:
    """The null replicates and their statistics.

    Parameters
    ----------
    scn : Scenario
        The nominal scenario (noise switches, engine settings).
    fitter : Fitter
        The record's, after calibration (its converter is set here).
    cal : Calibration
    n, seed : int
    progress : bool, optional

    Returns
    -------
    Null
    """
    prep = fitter.prep
    train = prep.folds()[-1]["train"]
    thetas = posterior_draws(cal, n, seed)
    raw = []
    records = loc.null_records(scn, [fitter.device(th) for th in thetas], prep, seed, progress=progress, raw=raw,
                               knobs=thetas, delay_s=fitter.delay_s, quadrature_polarity=fitter.quadrature_polarity)
    die_b = fitter.path(None)["die_b"]
    preds = [fitter.through_channels(th, fitter.table(th).evaluate(die_b, fitter.rate_b)) for th in thetas]
    fitter.set_converter(converter_model(prep, raw, preds))
    blocks = []
    for nr in records:
        Yn = np.column_stack([prep.block_mean(nr[c]) for c in CHANNELS])
        Yn[fitter.transient_b, IRATE] = np.nan  # as in the record's blocks
        blocks.append(Yn)
    # the auxiliary channels' own noise (the unit's data acquisition), which the simulated loop does not hold
    Z_rec = fitter.noise_residual(cal.lin.predict(cal.solution.x))
    lack = matched_noise(Z_rec, [fitter.noise_residual(p, Y=Yn) for p, Yn in zip(preds, blocks)], fitter.S, seed)
    blocks = [Yn + add for Yn, add in zip(blocks, lack)]
    ho_s = prep.heldout_mask_samples()
    ho_b, S_ho = heldout_blocks(prep), heldout_sigma(fitter)
    slow = loc.slow_templates(prep)
    win = window_masks(prep, train)
    laws = law_errors(fitter, train, len(records), seed)
    stats, windows, Z_noise, ms, a_ho, a_tr = [], [], [], [], [], []
    for nr, pred_k, Yn, law in zip(records, preds, blocks, laws):
        # against the replicate's own calibration on the same training blocks, as the record's residual is against
        # its own: on the training window a calibration absorbs part of the noise, and beyond it the estimate's error
        # and the laws' own error beyond the training temperatures
        pred_n = cal.lin.predict(fitter.solve(cal.lin, train, Y=Yn + law).x)
        Z_n = fitter.residual(pred_n, Y=Yn + law)
        stats.append(loc.residual_stats(prep, Z_n, rate_residual(prep, pred_n, nr["rate_V"])))
        windows.append(window_stats(prep, Z_n, win))
        # the noise alone (against the replicate's own device): the scoring noise model, the held-out noise level
        # and the flicker band
        rr = rate_residual(prep, pred_k, nr["rate_V"])
        Z_noise.append(fitter.residual(pred_k, scoring=True, Y=Yn))
        ms.append(heldout_metrics(fitter, ho_b, pred_k, Yn, S_ho))
        a_ho.append(loc.residual_allan(prep, rr, ho_s, slow)[1])
        a_tr.append(loc.residual_allan(prep, rr, ~ho_s, slow)[1])
    noise_ms = {k: float(np.mean([m[k] for m in ms if k in m])) for k in ms[0]} if ms else {}
    return Null(thetas, records, preds, blocks, stats, windows, pooled_noise_model(Z_noise), noise_ms, a_ho, a_tr,
                dict(fitter.converter))
