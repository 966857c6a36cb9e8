"""Labelled benchmark cases: simulated 'measured' records whose effects are withheld from the diagnoser.

A case is the nominal device perturbed within its unit-to-unit tolerances, plus zero, one or two
library effects with parameters drawn from their prior ranges (random sign where either is
plausible) and their amplitudes scaled so that the signature's signal-to-noise ratio - in units of
the record's own noise, flicker and converter included (:func:`signature_snr`) - hits a target
drawn log-uniformly from below to well above the detection limit (:data:`SNR_TARGET`), simulated
with the envelope engine and a fresh noise seed on a random temperature profile (holds and ramps
at random temperatures and rates, sometimes rate-table steps). Records go to
``cases/``; labels (effects, parameters, perturbations, seed, SNR) to ``labels/`` - a separate file
the diagnoser is never given.

Out-of-library cases (off by default: :attr:`CaseMix.p_ool`) carry no library effect but a disturbance
no library effect makes (:data:`OUT_OF_LIBRARY`), added to the rate output; the right verdict there is
"unexplained" (diagnosis methods section 3).
"""

from __future__ import annotations

import json
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from ..diagnosis.calibrate import calibrate, recalibrated
from ..diagnosis.data import prepare
from ..diagnosis.fitting import PATH_EFFECTS, Fitter
from ..diagnosis.forward import CHANNELS, IRATE
from ..diagnosis.likelihood import innovations, slow_state_fit
from ..diagnosis.model import EffectModel
from ..diagnosis.parameters import KnobSet, apply_nominal, flip_quadrature
from ..effects import MODELS, EffectSet, validate_effects
from ..envelope.engine import run_envelope
from ..profiles import PiecewiseProfile
from ..record import atomic_write_text, read_record, write_record
from ..scenario import load_scenario
from ..uncertainty import apply_channels

#: Case mix.
P_NULL, P_SINGLE = 0.20, 0.55
#: Range of the signature SNR the case generator aims at (log-uniform), from below to well above
#: the detection limit.
SNR_TARGET = (1.0, 1000.0)
#: Parameters that are not amplitudes (time constants, widths).
NOT_SCALED = ("tau_s", "width_K", "tau_h")
#: Fraction of an amplitude's physical range kept clear of its non-zero bounds in the cases (20x the
#: diagnosis's pin tolerance).
BOUND_MARGIN = 0.02
#: Effects that change only the noise (their SNR is analytic; they set the others' noise).
NOISE_LEVEL = ("quantization", "flicker_noise")
#: SNR tiers of the signature left after the nominal calibration absorbs what it can.
SNR_TIERS = ((0.0, 3.0, "below"), (3.0, 10.0, "near"), (10.0, np.inf, "above"))
#: Disturbances of the rate output that no library effect makes (diagnosis methods section 3 names a
#: sinusoidal electronics disturbance and a step): a bias wander that is a sine in time (period 20-80 min,
#: unrelated to temperature) and a bias step at a random time in the middle of the record (a charge or
#: shock event), rounded over 60 s.
OUT_OF_LIBRARY = ("bias_wander", "bias_step")
#: Largest out-of-library amplitude (deg/s) a case may reach while aiming at its SNR.
OOL_MAX_DPS = 2.0

#: Response tables shared by the Fitters of the case being made (:func:`make_case`). Each SNR calibrates the
#: nominal knobs afresh, from the data-sheet point, on records of one profile: the tables at that point and its
#: finite-difference steps recur in every calibration (about a third of a case's CPU, bit for bit the same).
_CASE_TABLES: ContextVar[dict | None] = ContextVar("case_tables", default=None)


class MixError(ValueError):
    """A case mix that cannot be drawn; ``field`` names the offending choice ("effects", "kind" or "snr")."""

    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class CaseMix:
    """What the benchmark's cases are drawn from.

    The default is the issue's mix: about 20 % null, 55 % one effect, 25 % two, over the whole library,
    SNR from below to well above the limit. A narrower mix aims the benchmark at one question (for example
    two look-alikes, single effects, above the limit); each case is drawn as in the default mix, from the
    narrower pool and SNR range.

    Attributes
    ----------
    effects : tuple of str
        The effects drawn from, in :data:`fmvmg_sim.effects.MODELS` order.
    p_null, p_single : float
        Fractions of null and single-effect cases; the rest have two effects.
    snr_range : tuple of float
        Signature SNR targets, drawn log-uniformly.
    p_ool : float
        Fraction of cases that are out of library (their drawn library effects replaced by a disturbance of
        :data:`OUT_OF_LIBRARY`); 0 by default, the issue's mix. It is drawn from its own random stream, so the
        other cases of a seed are the same whatever ``p_ool`` is.
    """

    effects: tuple = tuple(MODELS)
    p_null: float = P_NULL
    p_single: float = P_SINGLE
    snr_range: tuple = SNR_TARGET
    p_ool: float = 0.0

    #: ``--mix`` names: (p_null, p_single).
    KINDS: ClassVar[dict] = {"default": (P_NULL, P_SINGLE), "single": (0.0, 1.0), "pair": (0.0, 0.0),
                             "null": (1.0, 0.0)}

    @classmethod
    def build(cls, effects: list | None = None, kind: str = "default", snr_min: float = SNR_TARGET[0],
              snr_max: float = SNR_TARGET[1], ool_fraction: float = 0.0) -> "CaseMix":
        """A checked mix from command-line choices.

        Parameters
        ----------
        effects : list of str, optional
            Effect names (default None: the whole library; an empty list is an error).
        kind : {"default", "single", "pair", "null"}, optional
        snr_min, snr_max : float, optional
        ool_fraction : float, optional
            Fraction of out-of-library cases, in [0, 1).

        Returns
        -------
        CaseMix

        Raises
        ------
        MixError
            Naming what is wrong: an unknown effect, an unknown kind, too few effects for pairs, a bad SNR range
            or out-of-library fraction.
        """
        if effects is not None and not effects:
            raise MixError("effects", "no effect named")
        names = list(MODELS) if effects is None else list(dict.fromkeys(effects))
        unknown = [n for n in names if n not in MODELS]
        if unknown:
            raise MixError("effects", f"unknown effect {', '.join(unknown)} (known: {', '.join(MODELS)})")
        if kind not in cls.KINDS:
            raise MixError("kind", f"unknown mix {kind!r} (known: {', '.join(cls.KINDS)})")
        p_null, p_single = cls.KINDS[kind]
        if p_null + p_single < 1.0 and len(names) < 2:
            raise MixError("effects", f"mix {kind!r} has two-effect cases and needs at least two effects")
        if not (0.0 < snr_min < snr_max and np.isfinite(snr_max)):
            raise MixError("snr", f"SNR range [{snr_min:g}, {snr_max:g}] must satisfy 0 < min < max < inf")
        if not 0.0 <= ool_fraction < 1.0:
            raise MixError("ool", f"out-of-library fraction {ool_fraction:g} must lie in [0, 1)")
        return cls(tuple(n for n in MODELS if n in names), p_null, p_single, (float(snr_min), float(snr_max)),
                   float(ool_fraction))

    def as_dict(self) -> dict:
        """JSON-ready description (kept in ``scores.json``).

        Returns
        -------
        dict
        """
        return {"effects": list(self.effects), "p_null": self.p_null, "p_single": self.p_single,
                "snr_range": list(self.snr_range), "p_ool": self.p_ool}


def tier(snr: float) -> str:
    """SNR tier name.

    Parameters
    ----------
    snr : float

    Returns
    -------
    str
    """
    return next(n for lo, hi, n in SNR_TIERS if lo <= snr < hi)


def random_profile(rng: np.random.Generator, duration_s: float) -> tuple[list, list]:
    """A random oven profile: holds and ramps (0.3-2 K/min) between random temperatures in [-30, 70] C.

    Parameters
    ----------
    rng : Generator
    duration_s : float

    Returns
    -------
    temperature_points, rate_points : list of [t_s, value]
    """
    t, T = 0.0, float(rng.uniform(10, 35))
    pts = [[0.0, T]]
    while t < duration_s:
        if rng.random() < 0.4:
            t += float(rng.uniform(600, 2700))
        else:
            target = float(np.clip(T + rng.choice([-1, 1]) * rng.uniform(15, 60), -30, 70))
            if abs(target - T) < 5:
                target = T + (20 if T < 20 else -20)
            rate = float(rng.uniform(0.3, 2.0))
            t += abs(target - T) / rate * 60.0
            T = target
        pts.append([t, T])
    rpts = [[0.0, 0.0]]
    if rng.random() < 0.3:  # rate-table steps
        n = int(rng.integers(2, 5))
        for k in range(n):
            t0 = float(rng.uniform(0.1, 0.9) * duration_s)
            r = float(rng.choice([-1, 1]) * rng.uniform(10, 100))
            rpts += [[t0, 0.0], [t0 + 1.0, r], [t0 + 300.0, r], [t0 + 301.0, 0.0]]
        rpts = sorted(rpts)
        clean = [rpts[0]]
        for p in rpts[1:]:
            if p[0] > clean[-1][0]:
                clean.append(p)
        rpts = clean
    return pts, rpts


def inside(spec) -> tuple[float, float]:
    """The physical range of an amplitude pulled in by :data:`BOUND_MARGIN` of its width at non-zero bounds.

    A drawn or scaled value is clipped to this range: the diagnosis rejects a fit pinned at a
    physical bound (a zero bound is "no effect", not a pin), so a true value on the bound would be
    a case no admissible answer can get right.

    Parameters
    ----------
    spec : fmvmg_sim.effects.Param

    Returns
    -------
    lo, hi : float
    """
    w = BOUND_MARGIN * (spec.hi - spec.lo)
    return (spec.lo + w if spec.lo != 0.0 else 0.0), (spec.hi - w if spec.hi != 0.0 else 0.0)


def draw_effect(rng: np.random.Generator, name: str, scale: float) -> dict:
    """Parameters of one effect from its prior ranges, with its amplitude parameters scaled.

    Parameters
    ----------
    rng : Generator
    name : str
    scale : float
        Multiplies amplitude-like parameters (not time constants or widths).

    Returns
    -------
    dict
    """
    out = {}
    for p, s in MODELS[name].items():
        v = float(np.exp(rng.uniform(np.log(s.prior[0]), np.log(s.prior[1]))))
        if p not in NOT_SCALED:
            v *= scale
            if s.signed and rng.random() < 0.5:
                v = -v
        out[p] = float(np.clip(v, *(inside(s) if p not in NOT_SCALED else (s.lo, s.hi))))
    return out


def make_case(k: int, seed: int, out: Path, scenario_path: str, duration_s: float = 3 * 3600.0,
              output_rate_Hz: float = 1.0, mix: CaseMix | None = None) -> dict:
    """Generate case ``k``: write ``cases/case_k.csv`` and ``labels/case_k.json``.

    Parameters
    ----------
    k, seed : int
    out : Path
    scenario_path : str
        Nominal scenario.
    duration_s, output_rate_Hz : float, optional
    mix : CaseMix, optional
        What the case is drawn from (default: the issue's mix).

    Returns
    -------
    dict
        The label.
    """
    token = _CASE_TABLES.set({})
    try:
        return _make_case(k, seed, out, scenario_path, duration_s, output_rate_Hz, mix)
    finally:
        _CASE_TABLES.reset(token)


def _make_case(k: int, seed: int, out: Path, scenario_path: str, duration_s: float, output_rate_Hz: float,
               mix: CaseMix | None) -> dict:
    """:func:`make_case`'s work (its Fitters share their response tables)."""
    mix = mix or CaseMix()
    rng = np.random.default_rng([seed, k])
    u = rng.random()
    names = list(mix.effects)
    if u < mix.p_null:
        effects = []
    elif u < mix.p_null + mix.p_single:
        effects = [names[k % len(names)] if rng.random() < 0.5 else str(rng.choice(names))]
    else:
        effects = [str(x) for x in rng.choice(names, 2, replace=False)]
    target = float(np.exp(rng.uniform(np.log(mix.snr_range[0]), np.log(mix.snr_range[1]))))
    drawn = {n: draw_effect(rng, n, 1.0) for n in effects}
    ool = None
    if mix.p_ool > 0.0:  # its own stream: the other cases of the seed stay as they are without it
        rng_ool = np.random.default_rng([seed, k, 1])
        if rng_ool.random() < mix.p_ool:
            ool = draw_out_of_library(rng_ool, duration_s)
            effects, drawn = [], {}
    scn = load_scenario(scenario_path)
    # a unit and its data acquisition drawn across the nominal model's stated uncertainty: every knob uniformly
    # within its tolerance (unit values, temperature laws, channel offsets and gains), the quadrature of either sign
    knobs = KnobSet.of(scn.device_nominal)
    theta = {n: float(rng.uniform(-1, 1) * t) for n, t in zip(knobs.names, knobs.tolerance)}
    quad_sign = float(rng.choice([-1.0, 1.0]))
    unit = flip_quadrature(scn.device_nominal) if quad_sign < 0 else scn.device_nominal
    sim_seed = int(rng.integers(0, 2 ** 31))
    tp, rp = random_profile(rng, duration_s)
    s = scn.replace(scenario=dict(duration_s=duration_s, output_rate_Hz=output_rate_Hz, seed=sim_seed,
                                  fidelity="envelope"),
                    initial={"state": "steady"},
                    temperature=PiecewiseProfile(np.array([p[0] for p in tp]), np.array([p[1] for p in tp]), []),
                    rate=PiecewiseProfile(np.array([p[0] for p in rp]), np.array([p[1] for p in rp]), []))
    (out / "cases").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    path = out / "cases" / f"case_{k:04d}.csv"
    sf_nominal = scn.device_nominal.nominal_scale_factor_V_per_dps
    t_ref = scn.device_nominal.reference_temperature_C

    def simulate(eff):
        sim = s.replace(device=EffectSet(eff).apply_to_device(apply_nominal(unit, theta)), effects=eff)
        rec = recorded(run_envelope(sim, progress=False, log=lambda m: None).to_record(), theta, sf_nominal, t_ref)
        rec.metadata = {"device": scn.device.name, "source": "diagnose-benchmark case"}
        write_record(path, rec)

    # amplitudes scaled so that each effect's signature SNR hits the drawn target (log secant on the
    # quasi-static SNR, which needs only the record's time, temperature and applied rate). Noise-level
    # effects first (their SNR is analytic); the record's noise - white, flicker, a coarse converter -
    # then sets the SNR of the deterministic signatures (slow-state model of a noise-only twin)
    scales, snr_by = {}, {}
    for n in effects:
        if n in NOISE_LEVEL:
            scales[n], snr_by[n] = _scale_to(path, scenario_path, unit, theta, {n: drawn[n]}, target)
    noise_eff = validate_effects({n: scaled({n: drawn[n]}, scales[n])[n] for n in scales}, "case")
    twin = s.replace(scenario={"seed": int(rng.integers(0, 2 ** 31))},
                     device=EffectSet(noise_eff).apply_to_device(apply_nominal(unit, theta)), effects=noise_eff)
    noise = noise_model(recorded(run_envelope(twin, progress=False, log=lambda m: None).to_record(), theta, sf_nominal,
                                 t_ref),
                        unit, theta)
    eff = validate_effects(drawn, "case")
    simulate(eff)
    for n in effects:
        if n not in NOISE_LEVEL:
            scales[n], snr_by[n] = _scale_to(path, scenario_path, unit, theta, {n: drawn[n]}, target, noise=noise)
    if effects and any(v != 1.0 for v in scales.values()):
        eff = validate_effects({n: scaled({n: drawn[n]}, scales[n])[n] for n in effects}, "case")
        simulate(eff)
    if ool is not None:
        ool = add_out_of_library(path, ool, target, unit, noise)
    label = {"case": k, "record": str(path), "effects": eff, "nominal_deviation": theta, "quadrature_sign": quad_sign,
             "amplitude_scale": scales, "at_bound_by_effect": {n: at_bound(drawn[n], n, scales[n]) for n in effects},
             "snr_target": target if effects else 0.0, "snr_by_effect": snr_by,
             "sim_seed": s.seed, "temperature_points": tp, "rate_points": rp,
             "noise_model": {c: list(v) for c, v in zip(CHANNELS, noise) if v is not None}}
    label["snr"] = signature_snr(path, scenario_path, unit, theta, eff, noise=noise) if effects else 0.0
    # the former definition (white block noise only), kept so that scores can be compared across it
    white = {n: snr_by[n] if n in NOISE_LEVEL else signature_snr(path, scenario_path, unit, theta, {n: eff[n]})
             for n in effects}
    label["snr_white_by_effect"] = white
    label["tier_white"] = tier(min(white.values())) if effects else "null"
    # a pair is as detectable as its weaker member
    label["tier"] = tier(min(snr_by.values())) if effects else "null"
    # ... and as detectable beside its partner as what the partner cannot explain of it
    sep = separable_snr(path, unit, theta, eff, noise, snr_by) if effects else {}
    label["snr_separable_by_effect"] = sep
    label["tier_separable"] = tier(min(sep.values())) if effects else "null"
    # ... and as detectable as its training window carries it (a secondary tier: the limit is the
    # whole record's)
    label["snr_train"] = training_snr(path, unit, theta, eff, noise) if effects else 0.0
    label["tier_train"] = tier(label["snr_train"]) if effects else "null"
    if ool is not None:
        label.update(out_of_library=ool, snr_target=target, snr=ool["snr"], tier=tier(ool["snr"]),
                     tier_white=tier(ool["snr"]), tier_separable=tier(ool["snr"]), snr_train=None, tier_train=None)
    atomic_write_text(out / "labels" / f"case_{k:04d}.json", json.dumps(label, indent=1) + "\n")
    return label


def recorded(rec, theta: dict, sf_nominal: float, reference_temperature_C: float = 25.0):
    """A simulated record as the unit's data acquisition writes it: through the channel knobs of ``theta``
    (:func:`fmvmg_sim.uncertainty.apply_channels`), ``rate_dps`` the rate output over the nominal scale factor.

    Parameters
    ----------
    rec : Record
    theta : dict
    sf_nominal : float
    reference_temperature_C : float, optional
        The device's (the channels' gain coefficients are about it).

    Returns
    -------
    Record
    """
    cols = apply_channels(theta, {c: np.asarray(v, dtype=float) for c, v in rec.columns.items()},
                          reference_temperature_C)
    cols["rate_dps"] = cols["rate_V"] / sf_nominal
    return type(rec)(cols, rec.metadata, rec.path)


def unit_device(label: dict, device_nominal):
    """The nominal device with the quadrature sign of a case's unit (its label's ``quadrature_sign``).

    Parameters
    ----------
    label : dict
    device_nominal : Device

    Returns
    -------
    Device
    """
    return flip_quadrature(device_nominal) if label.get("quadrature_sign", 1.0) < 0 else device_nominal


def draw_out_of_library(rng: np.random.Generator, duration_s: float) -> dict:
    """Kind and shape of an out-of-library disturbance (:data:`OUT_OF_LIBRARY`), at unit amplitude.

    Parameters
    ----------
    rng : Generator
    duration_s : float
        Record length.

    Returns
    -------
    dict
        ``kind`` plus ``period_s`` and ``phase_rad`` (bias wander) or ``t_step_s`` and ``rise_s`` (bias step).
    """
    kind = str(rng.choice(OUT_OF_LIBRARY))
    if kind == "bias_wander":
        return {"kind": kind, "period_s": float(rng.uniform(1200.0, 4800.0)),
                "phase_rad": float(rng.uniform(0.0, 2 * np.pi))}
    return {"kind": kind, "t_step_s": float(rng.uniform(0.3, 0.8) * duration_s), "rise_s": 60.0}


def out_of_library_shape(ool: dict, t_s: np.ndarray) -> np.ndarray:
    """The disturbance of ``ool`` at unit amplitude (deg/s per deg/s) at times ``t_s``.

    Parameters
    ----------
    ool : dict
        From :func:`draw_out_of_library`.
    t_s : ndarray

    Returns
    -------
    ndarray
    """
    t_s = np.asarray(t_s, dtype=float)
    if ool["kind"] == "bias_wander":
        return np.sin(2 * np.pi * t_s / ool["period_s"] + ool["phase_rad"])
    if ool["kind"] == "bias_step":
        return 0.5 * (1.0 + np.tanh((t_s - ool["t_step_s"]) / (0.5 * ool["rise_s"])))
    raise ValueError(f"unknown out-of-library kind {ool['kind']!r} (known: {', '.join(OUT_OF_LIBRARY)})")


def add_out_of_library(path: Path, ool: dict, target: float, device_nominal, noise: list) -> dict:
    """Add an out-of-library disturbance to a case record's rate output, scaled to an SNR target.

    The disturbance enters before the converter (the rate output is put back on its lattice). Its SNR is
    that of its block means in the rate channel, whitened by the record's slow-state noise model (the one
    :func:`signature_snr` uses), before any calibration: the nominal knobs can absorb part of a slow
    disturbance, so this bounds from above what the diagnosis can see. The amplitude is linear in the SNR
    and capped at :data:`OOL_MAX_DPS`.

    Parameters
    ----------
    path : Path
        The case record, rewritten whole.
    ool : dict
        From :func:`draw_out_of_library`.
    target : float
        SNR target.
    device_nominal : Device
    noise : list
        Per-channel ``(rho, K, s)`` from :func:`noise_model`.

    Returns
    -------
    dict
        ``ool`` with ``amplitude_dps`` and ``snr``.
    """
    rec = read_record(path, warn_unknown=False)
    cols = {c: np.array(v, dtype=float) for c, v in rec.columns.items()}
    sf = device_nominal.nominal_scale_factor_V_per_dps
    fit = Fitter(prepare(rec, sf), device_nominal, tables=_CASE_TABLES.get())
    unit = out_of_library_shape(ool, cols["time_s"])
    z = fit.prep.block_mean(out_of_library_shape(ool, fit.prep.t_s) * sf) / fit.S[:, IRATE]
    rho, K, s_ = noise[IRATE]
    unit_snr = float(np.sqrt(np.nansum((innovations(z, rho, K) / s_) ** 2)))
    amp = float(min(target / unit_snr, OOL_MAX_DPS)) if unit_snr > 0 else 0.0
    lsb = float(device_nominal.values["noise"]["quantization_lsb_V"])
    v = cols["rate_V"] + amp * unit * sf
    cols["rate_V"] = np.round(v / lsb) * lsb if lsb > 0 else v
    # the record's own conversion of the output to deg/s (the nominal scale factor)
    m = np.isfinite(cols["rate_dps"]) & (cols["rate_dps"] != 0) & np.isfinite(rec.columns["rate_V"])
    sf_rec = float(np.median(rec.columns["rate_V"][m] / cols["rate_dps"][m])) if m.any() else sf
    cols["rate_dps"] = cols["rate_V"] / sf_rec
    write_record(path, type(rec)(cols, rec.metadata))
    return dict(ool, amplitude_dps=amp, snr=amp * unit_snr)


def _scale_to(record_path, scenario_path, device_nominal, theta: dict, drawn: dict, target: float,
              max_iter: int = 4, noise: list | None = None) -> tuple[float, float]:
    """Amplitude scale of ``drawn`` whose signature SNR is within 25 % of ``target`` (log secant).

    A step that takes the device outside the quasi-static model's domain (no steady oscillation,
    e.g. a Duffing term at its bound) is halved in log scale towards the last good one."""
    def snr_at(sc):
        try:
            return signature_snr(record_path, scenario_path, device_nominal, theta,
                                 validate_effects(scaled(drawn, sc), "case"), noise=noise)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            return None
    scale = 1.0
    snr = snr_at(scale)
    if snr is None:
        raise ValueError(f"effects {sorted(drawn)} at their drawn amplitudes are outside the model's domain")
    hist = [(scale, snr)]
    for _ in range(max_iter):
        if snr <= 0 or abs(np.log(snr / target)) < np.log(1.25):
            break
        p_ = 1.0
        if len(hist) > 1 and hist[-1][1] > 0 and hist[-2][1] > 0 and hist[-1][0] != hist[-2][0]:
            p_ = float(np.clip(np.log(hist[-1][1] / hist[-2][1]) / np.log(hist[-1][0] / hist[-2][0]), 0.25, 3.0))
        new = float(np.clip(scale * (target / snr) ** (1.0 / p_), 1e-4, 1e3))
        s_new = snr_at(new)
        for _back in range(4):
            if s_new is not None:
                break
            new = float(np.sqrt(new * scale))
            s_new = snr_at(new)
        if s_new is None:
            break
        scale, snr = new, s_new
        hist.append((scale, snr))
    return scale, float(snr)


def at_bound(params: dict, name: str, scale: float) -> bool:
    """Whether scaling effect ``name``'s drawn ``params`` by ``scale`` takes an amplitude to its bound.

    There :func:`scaled` clips it, and the signature SNR stays below its target whatever the scale: the record
    cannot show the effect at that target within its physical range (a hysteresis on a record held at one
    temperature, say).

    Parameters
    ----------
    params : dict
        The effect's drawn parameters.
    name : str
    scale : float

    Returns
    -------
    bool
    """
    for p, v in params.items():
        if p in NOT_SCALED or v * scale == 0.0:
            continue
        lo, hi = inside(MODELS[name][p])
        if not lo < v * scale < hi:
            return True
    return False


def scaled(effects: dict, scale: float) -> dict:
    """Effects with their amplitude-like parameters multiplied by ``scale`` (clipped to the bounds).

    Parameters
    ----------
    effects : dict
    scale : float

    Returns
    -------
    dict
    """
    out = {}
    for n, ps in effects.items():
        out[n] = {}
        for p, v in ps.items():
            sp = MODELS[n][p]
            out[n][p] = float(np.clip(v * scale, *inside(sp))) if p not in NOT_SCALED else v
    return out


def noise_model(record, device_nominal, theta: dict) -> list:
    """Slow-state noise model ``(rho, K, s)`` per channel of a noise-only record's block residual.

    The record is the case's device (nominal deviations and noise-level effects, no deterministic
    effect) simulated with noise; its blocks, normalised by their white sigma, against the noise-free
    quasi-static model hold the white noise, the flicker wander and the converter's staircase.

    Parameters
    ----------
    record : Record
    device_nominal : Device
    theta : dict

    Returns
    -------
    list
        One ``(rho, K, s)`` per channel of :data:`fmvmg_sim.diagnosis.forward.CHANNELS` (None if absent),
        ``s`` floored at 1 (the block sigma).
    """
    sf = device_nominal.nominal_scale_factor_V_per_dps
    fit = Fitter(prepare(record, sf), device_nominal, tables=_CASE_TABLES.get())
    fit.delay_s = theta.get("temperature_delay_s", 0.0)
    Z = fit.residual(fit.through_channels(theta, fit.table(theta).evaluate(fit.path(None)["die_b"], fit.rate_b)))
    out = []
    for c in range(Z.shape[1]):
        if np.isfinite(Z[:, c]).sum() > 10:
            rho, K, s = slow_state_fit([Z[:, c]])
            # the innovation sd is floored at the block sigma: the whitening may discount a slow signature
            # that slow noise hides, but never credit one beyond its white-noise SNR (a channel whose block
            # sigma is a model floor, like the drive frequency, would otherwise be whitened into 100s of sigma)
            out.append((rho, K, max(s, 1.0)))
        else:
            out.append(None)
    return out


def _calibrated_truth(record_path, device_nominal, theta: dict, det: dict, training: bool = False) -> tuple:
    """``(fit, cal)``: a :class:`~.fitting.Fitter` on the record's profile whose observations are the noise-free
    quasi-static truth of the device ``theta`` with the deterministic effects ``det`` (absent channels stay
    absent), and the nominal knobs calibrated to it on every block (``training``: on the diagnoser's training
    window, the last forward-chained fold's training blocks)."""
    rec = read_record(record_path, warn_unknown=False)
    sf = device_nominal.nominal_scale_factor_V_per_dps
    prep = prepare(rec, sf)
    fit = Fitter(prep, device_nominal, tables=_CASE_TABLES.get())
    fit.delay_s = theta.get("temperature_delay_s", 0.0)  # the temperature the unit saw
    path = fit.path({n: v for n, v in det.items() if n in PATH_EFFECTS})
    truth = fit.through_channels(theta, fit.table(theta, det, quad=True, rate=True).evaluate(
        path["die_b"], path["rate_b"], path["quad_b"]))
    truth[:, ~fit.present] = np.nan
    fit.Y = truth

    def new_fitter():
        f = Fitter(prep, device_nominal, tables=_CASE_TABLES.get())
        f.Y = truth
        return f

    rows = fit.prep.folds()[-1]["train"] if training else np.ones(fit.prep.n_blocks, bool)
    # calibrated as the diagnosis calibrates (from its other starts too): what the diagnosis' calibration absorbs of
    # the unit is not the effect's signature
    fit, cal = recalibrated(fit, calibrate(fit, rows), rows, new_fitter)
    fit.delay_s = cal.theta.get("temperature_delay_s", 0.0)
    return fit, cal


def _whitened_norm(fit, pred: np.ndarray, noise: list, rows: np.ndarray | None = None) -> float:
    """``sqrt(chi^2)`` of the truth's residual against ``pred``, each channel whitened by its noise model
    (the whole record filtered, the blocks ``rows`` summed; default all)."""
    R = fit.residual(pred)
    rows = np.ones(R.shape[0], bool) if rows is None else rows
    chi2 = sum(float(np.nansum((innovations(R[:, c], p[0], p[1])[rows] / p[2]) ** 2))
               for c, p in enumerate(noise) if p is not None and np.isfinite(R[:, c]).any())
    return float(np.sqrt(chi2))


def _noise_level_snr(effects: dict, device_nominal) -> float:
    """Analytic SNR of the noise-level effects in ``effects`` (0 without one): ``10 x`` their added
    variance over the nominal one in their band."""
    snr = 0.0
    nz = device_nominal.values["noise"]
    if "quantization" in effects:
        snr = max(snr, 10 * (effects["quantization"]["lsb_V"] ** 2 - nz["quantization_lsb_V"] ** 2) / 12 / (8e-4) ** 2)
    if "flicker_noise" in effects:
        f = effects["flicker_noise"]
        base = nz["flicker_output_dps2"] + nz["flicker_phase_rad2"] * np.deg2rad(200.0) ** 2 * (180 / np.pi) ** 2
        snr = max(snr, 10 * (f["h_output_dps2"] + f["h_phase_rad2"] * (200.0) ** 2) / base)
    return float(snr)


def signature_snr(record_path, scenario_path, device_nominal, theta: dict, effects: dict,
                  noise: list | None = None) -> float:
    """Signal-to-noise ratio of the effects' signature that the nominal calibration cannot absorb.

    The noise-free truth (quasi-static model of the perturbed device with the effects) replaces the
    record's blocks; the calibrated nominal model's residual, whitened by the record's noise model
    (white, flicker and converter noise: :func:`noise_model`; white block noise alone without one),
    has norm ``sqrt(chi^2)``: the SNR. Noise-level effects: ``10 x`` their added variance over the
    nominal one in their band.

    Parameters
    ----------
    record_path : path-like
    scenario_path : path-like
    device_nominal : Device
    theta, effects : dict
    noise : list, optional
        Per-channel ``(rho, K, s)`` from :func:`noise_model`.

    Returns
    -------
    float
    """
    return _snr(record_path, device_nominal, theta, effects, noise)


def training_snr(record_path, device_nominal, theta: dict, effects: dict, noise: list) -> float:
    """SNR of the effects' signature on the diagnoser's training window, after the nominal calibration there.

    As :func:`signature_snr`, but the nominal knobs are calibrated on the last forward-chained fold's training
    blocks (the window on which the diagnosis calibrates, fits each candidate and computes its Delta-BIC) and
    the chi-square is summed over those blocks. An effect whose signature lies in the held-out end of the
    record (a temperature-rate term whose only fast ramp comes last) has a high whole-record SNR and a low
    training one: forward-chained attribution cannot fit what its training window does not carry.

    Parameters
    ----------
    record_path : path-like
    device_nominal : Device
    theta, effects : dict
        The case's nominal deviations and (scaled) effects.
    noise : list
        Per-channel ``(rho, K, s)`` from :func:`noise_model`.

    Returns
    -------
    float
        The noise-level effects' analytic SNR (:func:`signature_snr`) when that is larger: their band is read
        on the whole record; 0 without effects.
    """
    return _snr(record_path, device_nominal, theta, effects, noise, training=True)


def _snr(record_path, device_nominal, theta: dict, effects: dict, noise: list | None,
         training: bool = False) -> float:
    """:func:`signature_snr` (every block) or :func:`training_snr` (``training``: the training window)."""
    if not effects:
        return 0.0
    snr_noise = _noise_level_snr(effects, device_nominal)
    det = {n: v for n, v in effects.items() if n not in NOISE_LEVEL}
    if not det:
        return snr_noise
    fit, cal = _calibrated_truth(record_path, device_nominal, theta, det, training=training)
    if noise is None:
        return float(max(np.sqrt(cal.solution.cost), snr_noise))
    rows = fit.prep.folds()[-1]["train"] if training else None
    return float(max(_whitened_norm(fit, cal.lin.predict(cal.solution.x), noise, rows), snr_noise))


def _snr_beyond(fit, cal, names: list, noise: list) -> float:
    """SNR of ``fit``'s truth left after the calibrated knobs and the effects ``names`` (fitted on every block)."""
    if not names:
        return _whitened_norm(fit, cal.lin.predict(cal.solution.x), noise)
    mf = EffectModel(fit, cal, sorted(names)).fit(np.ones(fit.prep.n_blocks, bool))
    return _whitened_norm(fit, mf._ctx["pred"], noise)


def snr_beyond(record_path, device_nominal, theta: dict, effects: dict, noise: list, explained_by: list) -> float:
    """SNR of the true signature that ``explained_by`` cannot explain.

    The noise-free truth of ``effects`` (as in :func:`signature_snr`) is fitted with the nominal knobs and the
    deterministic effects ``explained_by`` (parameters free, the nonlinear one searched) on every block; the
    residual, whitened by the record's noise model, has norm ``sqrt(chi^2)``. Below the detection limit, no
    criterion on this record can prefer the truth to ``explained_by`` (a diagnosis that answered
    ``explained_by`` was wrong, but the record could not say so).

    Parameters
    ----------
    record_path : path-like
    device_nominal : Device
    theta, effects : dict
        The case's nominal deviations and (scaled) effects.
    noise : list
        Per-channel ``(rho, K, s)`` from :func:`noise_model`.
    explained_by : list of str
        Effect names (noise-level ones are left out: they absorb no deterministic signature).

    Returns
    -------
    float
        0 when ``effects`` has no deterministic effect.
    """
    det = {n: v for n, v in effects.items() if n not in NOISE_LEVEL}
    if not det:
        return 0.0
    fit, cal = _calibrated_truth(record_path, device_nominal, theta, det)
    return _snr_beyond(fit, cal, [n for n in explained_by if n not in NOISE_LEVEL], noise)


def separable_snr(record_path, device_nominal, theta: dict, effects: dict, noise: list,
                  snr_by: dict) -> dict:
    """SNR of each member of a pair beyond what its partner can explain.

    A pair is told apart from one of its members alone only by the part of the other's signature that
    the member (with the nominal knobs) cannot absorb: for two deterministic members, :func:`snr_beyond`
    of the pair's truth with the partner as the explanation. A look-alike partner can leave next to
    nothing (a Q drift beside a reference drift whose rectifier part moves the AGC effort the other way),
    however strong each member is alone. A noise-level member and a deterministic signature do not
    absorb each other: each keeps ``snr_by``.

    Parameters
    ----------
    record_path : path-like
    device_nominal : Device
    theta, effects : dict
        The case's nominal deviations and (scaled) effects.
    noise : list
        Per-channel ``(rho, K, s)`` from :func:`noise_model`.
    snr_by : dict
        Each member's own SNR (:func:`signature_snr` of it alone).

    Returns
    -------
    dict
        Effect -> SNR beyond its partner (``snr_by`` for a single effect, or where the partner's fit
        leaves the model's domain).
    """
    out = dict(snr_by)
    det = {n: v for n, v in effects.items() if n not in NOISE_LEVEL}
    if len(effects) != 2 or len(det) != 2:
        return out
    fit, cal = _calibrated_truth(record_path, device_nominal, theta, det)
    for n in det:
        try:
            out[n] = _snr_beyond(fit, cal, [m for m in det if m != n], noise)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            continue
    return out
