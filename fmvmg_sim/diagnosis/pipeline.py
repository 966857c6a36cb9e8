"""The whole diagnosis of one record, as a short sequence of stages.

1. **Inputs**: read and check the record, and the nominal device with its stated uncertainty (:func:`load_inputs`).
2. **Calibration**: the nominal knobs (unit values, temperature laws, channel offsets and gains) fitted on the
   training window within their tolerances (:func:`.calibrate.calibrate`).
3. **Null**: the calibrated unit re-simulated with its noise on the record's inputs (:func:`.null.simulate_null`).
4. **Localisation**: where the record leaves the null band (:func:`localise`).
5. **Attribution**: every library effect fitted and scored on held-out blocks, then the decision rules
   (:func:`.attribution.attribute`, :mod:`.rules`).
6. **Noise-level effects**: a coarser converter and extra flicker (:mod:`.noise_effects`).
7. **Verdict** (:func:`.rules.verdict`) and what the record could not have shown (:mod:`.detection`).
8. **Report** (:func:`.report.assemble`): docs/formats.md section 4 and more; :mod:`.report` writes it as JSON and
   Markdown, :mod:`.plots` draws the figures.
"""

from __future__ import annotations

import itertools
import sys
import time
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from ..effects import MODELS
from ..errors import InputError
from ..record import Record, read_record
from ..scenario import load_scenario
from . import localize as loc
from .attribution import CandidateFitter, attribute
from .calibrate import calibrate, recalibrated, release_gains, resolution
from .data import Prepared, difference_sigma, prepare
from .detection import detection_limits
from .fitting import DEVICE_EFFECTS, Fitter
from .forward import CHANNELS, IQUAD, IRATE
from .heldout import Scorer
from .likelihood import slow_state_fit
from .noise_effects import FlickerBand, quantization_candidate
from .null import N_NULL, NOISE_SD_FLOOR, Null, accuracy_floored, rate_residual, simulate_null
from .parameters import flip_quadrature
from .report import assemble
from .rules import verdict

#: Die-temperature accuracy of the model (K): a floor on every channel's scoring sigma (its temperature
#: sensitivity times this). The forward model's block means track the envelope engine's to 1e-4 K in
#: drive-frequency terms (tests/test_diagnosis_forward.py); 20x that leaves margin for fitted thermal paths.
DIE_FLOOR_K = 0.002
#: Largest |rate bias| accepted, in multiples of the device's own scale (its largest predicted bias plus 1 deg/s),
#: beyond the largest bias a library effect inside its physical bounds makes on the record (:func:`library_bias_dps`):
#: beyond both the rate is in another unit (milli-degrees per second written as degrees).
BIAS_SCALE_MAX = 30.0
#: Factor within which a record's auxiliary channel must match the device's magnitude.
MAGNITUDE_FACTOR = 30.0

__all__ = ["N_NULL", "diagnose", "load_inputs", "calibrated", "localise", "record_scale_factor", "check_units",
           "library_bias_dps"]


def diagnose(record_path, scenario_path, n_null: int = N_NULL, seed: int = 0, progress: bool | None = None,
             log=None) -> dict:
    """Diagnose the sim-to-real gap of a record against a nominal scenario.

    Parameters
    ----------
    record_path : path-like
        Record (docs/formats.md section 2), CSV or gzipped CSV.
    scenario_path : path-like
        Nominal scenario: device, circuit, noise and tolerances (time, temperature and rate come from the record).
    n_null : int, optional
        Null re-simulations.
    seed : int, optional
        Seed of the null re-simulations.
    progress : bool, optional
        Progress bars on stderr (default: for records longer than 4 h).
    log : callable, optional
        Receives one line per stage (default: stderr).

    Returns
    -------
    dict
        The report (docs/formats.md section 4 and more); private arrays for the plots under ``"_plot"``.

    Raises
    ------
    InputError
        Bad record or scenario.
    """
    # the fits are small dense problems: BLAS threads only spin against each other (and against other processes)
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(record_path, scenario_path, n_null, seed, progress,
                         log or (lambda m: sys.stderr.write(m + "\n")))


def _diagnose(record_path, scenario_path, n_null: int, seed: int, progress, log) -> dict:
    """:func:`diagnose`'s stages."""
    wall0 = time.perf_counter()
    scn, prep = load_inputs(record_path, scenario_path)
    show = progress if progress is not None else prep.duration_s > 4 * 3600
    train = prep.folds()[-1]["train"]
    fitter, cal = calibrated(prep, scn.device_nominal, train)
    cal.release_gain = release_gains(fitter, cal.lin, train, cal.at_bound)
    die_b = fitter.path(None)["die_b"]
    fitter.set_score_floor(cal.base, die_b, DIE_FLOOR_K)
    fitter.set_law_accuracy(cal.base, die_b, train)
    log(f"calibrated {len(cal.theta)} knobs on {int(train.sum())} training blocks; at their bound: "
        f"{', '.join(cal.at_bound) or 'none'} (asked there by the record: {', '.join(cal.asked_at_bound) or 'none'})")
    null = simulate_null(scn, fitter, cal, n_null, seed, progress=show)
    where = localise(fitter, cal, null)
    log(f"localisation: {len(where.significant)} statistics beyond the null band")
    # scored at no better than the calibrated model's own accuracy on the record's auxiliary channels
    noise = accuracy_floored(null.noise_params, fitter.residual(cal.lin.predict(cal.solution.x), scoring=True)[train])
    scorer = Scorer(fitter, cal, noise, null.noise_ms)
    flicker = FlickerBand(prep, null.allan_heldout, null.allan_train)
    cands = CandidateFitter(scorer, closure=lambda pred: closes(fitter, where, null, pred),
                            flicker=lambda pred: record_rate_noise(fitter, flicker, scorer, pred))
    att = attribute(cands, bool(where.significant), progress=show)
    log(f"attribution: {', '.join(att.selected) or 'no effect'} ({', '.join(r['rule'] for r in att.fired) or '-'})")
    quant = quantization_candidate(prep, scn.device.values["noise"]["quantization_lsb_V"])
    final_tr = att.final.fit._ctx["pred"] if att.final else cal.lin.predict(cal.solution.x)
    final_ho = att.final.preds["heldout"] if att.final else scorer.nominal["heldout"]
    band = flicker.judge(rate_residual(prep, np.where(np.isfinite(final_ho), final_ho, final_tr), prep.obs["rate_V"]))
    flick_ok = bool(band["raised"] and not quant and not band["wander"])
    accepted = (["quantization"] if quant else []) + att.selected + (["flicker_noise"] if flick_ok else [])
    accepted = accepted[:2]
    closure = closure_of(fitter, where, null, final_tr) if att.final is not None and not flick_ok else None
    v = verdict(accepted, att.ambiguous, bool(where.significant), bool(closure and closure["open"]))
    limits = detection_limits(scorer)
    return assemble(record_path=record_path, prep=prep, fitter=fitter, cal=cal, null=null, where=where,
                    scorer=scorer, att=att, quant=quant, band=band, flick_ok=flick_ok, accepted=accepted,
                    closure=closure, verdict=v, limits=limits, n_null=n_null, seed=seed,
                    wall_s=time.perf_counter() - wall0)


def load_inputs(record_path, scenario_path) -> tuple:
    """Read the record and the scenario and check them against each other.

    Parameters
    ----------
    record_path, scenario_path : path-like

    Returns
    -------
    scenario : Scenario
    prep : Prepared

    Raises
    ------
    InputError
    """
    scn = load_scenario(scenario_path)
    rec = read_record(record_path)
    prep = prepare(rec, record_scale_factor(rec, scn.device_nominal))
    fitter = Fitter(prep, scn.device_nominal)
    check_units(rec, prep, fitter.table({}).evaluate(fitter.path(None)["die_b"], fitter.rate_b), fitter)
    return scn, prep


def calibrated(prep: Prepared, device, train: np.ndarray) -> tuple:
    """The nominal model calibrated on the training window, in the quadrature convention the record shows.

    A unit's quadrature coupling has either sign, and the record's quadrature output either polarity (which way
    its reference is wired): the two combinations that give the quadrature output the record's sign
    (:func:`quadrature_conventions`) turn the demodulated outputs the opposite ways with the phase error, so that
    the bias the quadrature leaks has the one sign or the other. Each is calibrated from the data-sheet point, then
    again from the Q law's other form (:func:`.calibrate.law_starts`) and from the Q law and effort channel that
    fit the AGC effort alone (:func:`.effort_law.effort_law_start`); a calibration from another start replaces the
    first when it fits the training window better by more than the calibration's resolution
    (:func:`.calibrate.resolution`: where an unmodelled effect dominates the misfit, a start's small gain is the
    effect's trade with the laws, not the unit). The convention that fits better from the data-sheet point is kept
    unless the other, from all its starts, fits better by more than that resolution: from the data-sheet point
    alone the wrong one can fit better with its knobs at their bounds while the right one has not yet left a law's
    wrong form, and where an unmodelled effect dominates the misfit the two trade with it by less than the
    resolution.

    Parameters
    ----------
    prep : Prepared
    device : Device
        The scenario's nominal device.
    train : ndarray of bool

    Returns
    -------
    fitter : Fitter
    cal : Calibration
    """
    runs = []
    for dev, polarity in quadrature_conventions(prep, device):
        def new_fitter(dev=dev, polarity=polarity):
            return Fitter(prep, dev, quadrature_polarity=polarity)
        f = new_fitter()
        first = calibrate(f, train)
        runs.append((first.objective, recalibrated(f, first, train, new_fitter)))
    runs.sort(key=lambda r: r[0])
    f, cal = runs[0][1]
    for _, (f_other, cal_other) in runs[1:]:
        if cal_other.objective < cal.objective - resolution(cal.objective):
            f, cal = f_other, cal_other
    f.delay_s = cal.theta.get("temperature_delay_s", 0.0)
    return f, cal


def quadrature_conventions(prep: Prepared, device) -> list:
    """The quadrature sign and output polarity combinations that give the record's quadrature output its sign.

    Parameters
    ----------
    prep : Prepared
    device : Device

    Returns
    -------
    list of (Device, float)
        ``(device, polarity)``: the device as it is or with its quadrature coupling of the other sign, and the
        output's polarity (+1 or -1); one combination without a quadrature channel.
    """
    if "quadrature_V" not in prep.channels:
        return [(device, 1.0)]
    fit = Fitter(prep, device)
    pred = fit.table({}).evaluate(fit.path(None)["die_b"])[:, IQUAD]
    same = np.sign(np.nanmedian(prep.block_obs()[:, IQUAD])) * np.sign(np.nanmedian(pred)) >= 0
    flipped = flip_quadrature(device)
    return [(device, 1.0), (flipped, -1.0)] if same else [(flipped, 1.0), (device, -1.0)]


def record_scale_factor(rec: Record, device) -> float:
    """The scale factor that converts the record's ``rate_V`` to its ``rate_dps``: its own
    ``# scale_factor_V_per_dps`` metadata when it states one, else the device's nominal one.

    Parameters
    ----------
    rec : Record
    device : Device
        The scenario's nominal device.

    Returns
    -------
    float
        V per deg/s.
    """
    try:
        sf = float(rec.metadata.get("scale_factor_V_per_dps", "nan"))
    except ValueError:
        sf = float("nan")
    return sf if np.isfinite(sf) and sf != 0.0 else device.nominal_scale_factor_V_per_dps


def library_bias_dps(fitter: Fitter, nominal_pred: np.ndarray) -> float:
    """Largest rate bias (deg/s) one library effect inside its physical bounds adds to the nominal device's on the
    record's temperatures: each device effect of :data:`fmvmg_sim.effects.MODELS` at every corner of its parameters'
    bounds (a corner with no operating point, a Duffing stiffness past the drive loop's reach, is skipped).

    Parameters
    ----------
    fitter : Fitter
        On the record, with the scenario's nominal device.
    nominal_pred : ndarray, shape (n_blocks, C)
        Nominal forward prediction.

    Returns
    -------
    float
    """
    sf = fitter.prep.sf_nominal_V_per_dps
    die = fitter.path(None)["die_b"]
    out = 0.0
    for name in DEVICE_EFFECTS:
        spec = MODELS[name]
        for corner in itertools.product(*((p.lo, p.hi) for p in spec.values())):
            try:
                pred = fitter.table({}, {name: dict(zip(spec, map(float, corner)))}).evaluate(die, fitter.rate_b)
            except (ValueError, RuntimeError, FloatingPointError):
                continue
            d = np.abs(pred[:, IRATE] - nominal_pred[:, IRATE]) / sf
            if np.isfinite(d).any():
                out = max(out, float(np.nanmax(d)))
    return out


def check_units(rec: Record, prep: Prepared, nominal_pred: np.ndarray, fitter: Fitter | None = None) -> None:
    """Refuse a record whose magnitudes do not match the scenario's device (a rate 1000x off, a channel in mV).

    Parameters
    ----------
    rec : Record
    prep : Prepared
    nominal_pred : ndarray, shape (n_blocks, C)
        Nominal forward prediction.
    fitter : Fitter, optional
        On the record: a rate bias beyond the device's own scale is then accepted up to the largest a library
        effect makes (:func:`library_bias_dps`), since the diagnosis can name it.

    Raises
    ------
    InputError
    """
    name = rec.path or "record"
    sf = prep.sf_nominal_V_per_dps
    r = np.asarray(rec["rate_dps"], dtype=float)
    if "rate_V" in rec.columns and np.isfinite(rec["rate_V"]).any():
        v = np.asarray(rec["rate_V"], dtype=float)
        ok = np.isfinite(r) & np.isfinite(v) & (np.abs(r) > 1e-9)
        if ok.sum() > 10:
            ratio = float(np.median(v[ok] / r[ok]))
            if not (sf / MAGNITUDE_FACTOR < abs(ratio) < sf * MAGNITUDE_FACTOR):
                raise InputError(f"rate_V / rate_dps = {ratio:.4g} V per deg/s, but the scenario's device has a "
                                 f"nominal scale factor of {sf:.4g} V per deg/s: rate_dps is in the wrong unit "
                                 f"(about {sf / ratio:.3g}x off)", f"{name}: rate_dps")
    # the in-phase (rate) and quadrature outputs demodulate the same pick-off: their white noise in volts agrees
    # (within a few percent on the simulator's and independently generated records), whatever the unit's biases
    if "quadrature_V" in rec.columns:
        s_rate = difference_sigma((r - prep.rate_true_dps) * sf, empty=0.0)
        s_quad = difference_sigma(np.asarray(rec["quadrature_V"], dtype=float), empty=0.0)
        if s_rate > 0 and s_quad > 0 and not (1 / MAGNITUDE_FACTOR < s_rate / s_quad < MAGNITUDE_FACTOR):
            raise InputError(f"the white noise of rate_dps x the nominal scale factor ({s_rate:.3g} V) is "
                             f"{s_rate / s_quad:.3g}x that of quadrature_V ({s_quad:.3g} V), which demodulates the "
                             f"same pick-off: rate_dps is in the wrong unit (is the rate in deg/s?)",
                             f"{name}: rate_dps")
    bias = float(np.nanmedian(r - prep.rate_true_dps))
    scale = float(np.nanmax(np.abs(nominal_pred[:, IRATE] / sf))) + 1.0
    if abs(bias) > BIAS_SCALE_MAX * scale:
        effects_dps = library_bias_dps(fitter, nominal_pred) if fitter is not None else 0.0
        if abs(bias) > BIAS_SCALE_MAX * scale + effects_dps:
            raise InputError(f"rate_dps bias {bias:.4g} deg/s is {abs(bias) / scale:.3g}x the device's scale "
                             f"({scale:.3g} deg/s) and beyond the {effects_dps:.3g} deg/s any library effect "
                             f"makes: wrong unit (is the rate in deg/s?)", f"{name}: rate_dps")
    for c, lo_abs in (("quadrature_V", 1e-3), ("agc_effort_V", 1e-3), ("drive_amplitude_V", 1e-3)):
        if c in prep.channels:
            i = CHANNELS.index(c)
            m = float(np.nanmedian(np.abs(prep.obs[c])))
            p = float(np.nanmedian(np.abs(nominal_pred[:, i])))
            if p > lo_abs and not (p / MAGNITUDE_FACTOR < m < p * MAGNITUDE_FACTOR):
                raise InputError(f"median |{c}| = {m:.4g} but the scenario's device gives about {p:.4g} "
                                 f"({m / max(p, 1e-30):.3g}x off): wrong unit or wrong device", f"{name}: {c}")


@dataclass
class Localisation:
    """Where the record leaves the null band.

    Attributes
    ----------
    stats : dict
        The record's statistics (:func:`.localize.residual_stats`) against its calibrated model.
    comparison : dict
        Each statistic against the null (:func:`.localize.compare`).
    significant : list
        ``(group, name, p_holm)`` beyond the band, most significant first.
    located : list
        The significant statistics that locate the gap in time or band (:data:`.localize.LOCATED`).
    """

    stats: dict
    comparison: dict
    significant: list
    located: list


def localise(fitter: Fitter, cal, null: Null) -> Localisation:
    """The record's residual statistics against the calibrated model, compared with the null's (Holm-corrected).

    Parameters
    ----------
    fitter : Fitter
    cal : Calibration
    null : Null

    Returns
    -------
    Localisation
    """
    prep = fitter.prep
    pred = cal.lin.predict(cal.solution.x)
    st = loc.residual_stats(prep, fitter.residual(pred), rate_residual(prep, pred, prep.obs["rate_V"]))
    comp = loc.compare(st, null.stats)
    sig = loc.significant(comp)
    return Localisation(st, comp, sig, [s for s in sig if s[0] in loc.LOCATED])


def closure_of(fitter: Fitter, where: Localisation, null: Null, pred_train: np.ndarray) -> dict | None:
    """Whether a model closes the located gap: its training-window fit, predicted over the whole record, read with
    the same statistics against the same null (:func:`.localize.closure`; None without a located gap).

    Parameters
    ----------
    fitter : Fitter
    where : Localisation
    null : Null
    pred_train : ndarray

    Returns
    -------
    dict or None
    """
    if not where.located:
        return None
    prep = fitter.prep
    st = loc.residual_stats(prep, fitter.residual(pred_train), rate_residual(prep, pred_train, prep.obs["rate_V"]))
    return loc.closure(where.comparison, st, null.stats)


def closes(fitter: Fitter, where: Localisation, null: Null, pred_train: np.ndarray) -> bool | None:
    """:func:`closure_of` as a yes or no (None without a located gap).

    Parameters
    ----------
    fitter : Fitter
    where : Localisation
    null : Null
    pred_train : ndarray

    Returns
    -------
    bool or None
    """
    c = closure_of(fitter, where, null, pred_train)
    return None if c is None else not c["open"]


def record_rate_noise(fitter: Fitter, flicker: FlickerBand, scorer: Scorer, pred_train: np.ndarray) -> tuple | None:
    """The rate output's slow-state noise model fitted to what a model leaves on the training window, when the
    record carries more flicker than the null there (None otherwise).

    Parameters
    ----------
    fitter : Fitter
    flicker : FlickerBand
    scorer : Scorer
    pred_train : ndarray

    Returns
    -------
    tuple or None
        ``(rho, K, s)``.
    """
    band = flicker.judge(rate_residual(fitter.prep, pred_train, fitter.prep.obs["rate_V"]))
    if not band["raised"]:
        return None
    z = fitter.residual(pred_train, scoring=True)[scorer.train][:, IRATE]
    rho, K, s = slow_state_fit([z])
    return rho, K, max(s, NOISE_SD_FLOOR)
