"""Run a scenario at carrier level: the compiled step rolled out with temperature and rate as inputs.

The run is cut into output samples of ``M`` steps. Each sample has its parameter
vector: the discretised diagram at the sample's temperature (cached per 1 mK), the
input rate, and the demodulation-phase flicker. Noise draws come from one seeded
generator in a fixed order, so a seed gives the same record bit for bit.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from tqdm import tqdm

from .. import noise as noisegen
from ..averaged import scale_factor_V_per_dps
from ..diagram import build_diagram
from ..effects import EffectSet
from ..result import SimResult
from ..scenario import Scenario
from ..compiled import load_rollout
from .plan import initial_state, make_plan
from .step import CARRIER_MODEL, N_NOISE, PARAMS, STATE

STATE_P = PARAMS.size

#: Temperatures are rounded to this step (K) when caching discretised operating points.
T_QUANTUM_K = 1e-3
#: Target number of simulated seconds per compiled call (progress-bar granularity).
CALL_S = 0.02


def _state(X, name):
    return X[:, STATE.slices[name]]


def run_carrier(scn: Scenario, progress: bool | None = None, log=None) -> SimResult:
    """Simulate ``scn`` at carrier level.

    Parameters
    ----------
    scn : Scenario
    progress : bool, optional
        Show a progress bar on stderr (default: when the run is expected to take > 3 s).
    log : callable, optional
        One-line messages (default: stderr).

    Returns
    -------
    SimResult
    """
    log = log or (lambda m: sys.stderr.write(m + "\n"))
    wall0 = time.perf_counter()
    dev = scn.device
    st = scn.settings["scenario"]
    ref = build_diagram(dev, dev.reference_temperature_C)
    f_ref = ref.resonator.f_drive_Hz
    spc = int(st["steps_per_cycle"])
    h = 1.0 / (spc * f_ref)
    M = max(1, int(round(1.0 / (st["output_rate_Hz"] * h))))
    dt_out = M * h
    n = int(np.ceil(scn.duration_s / dt_out - 1e-9))
    t_end = (np.arange(n) + 1) * dt_out
    t_mid = t_end - dt_out / 2
    case_mid = np.asarray(scn.temperature(t_mid), dtype=float)
    fx = EffectSet(scn.effects)
    temp = fx.die_temperature(t_mid, case_mid)
    sig = fx.signals(t_mid, temp)
    rate_dps = np.asarray(scn.rate(t_mid), dtype=float) + sig["rate_dps"]
    rate_end = np.asarray(scn.rate(t_end), dtype=float)
    vref_f = np.asarray(scn.vref_factor(t_mid), dtype=float)
    rng = np.random.default_rng(scn.seed)
    nz = scn.noise
    # slow noises at the output rate, drawn first so they do not depend on call sizes
    phase_flicker = (noisegen.flicker(n, 1.0 / dt_out, dev.values["noise"]["flicker_phase_rad2"], rng)
                     if nz["flicker"] else np.zeros(n))
    sf_nom = scale_factor_V_per_dps(build_diagram(scn.device_nominal, dev.reference_temperature_C))
    out_flicker_V = (noisegen.flicker(n, 1.0 / dt_out, dev.values["noise"]["flicker_output_dps2"], rng) * sf_nom
                     if nz["flicker"] else np.zeros(n))
    rrw_V = (noisegen.random_walk(n, 1.0 / dt_out, dev.values["noise"]["rate_random_walk_dps_per_sqrt_s"], rng)
             * sf_nom if nz["rate_random_walk"] else np.zeros(n))
    noise_on = {"brownian": nz["brownian"], "electronic": nz["electronic"]}
    scale = ref.core_state_scale()
    plans: dict[float, object] = {}
    keys = np.round(temp / T_QUANTUM_K) * T_QUANTUM_K  # operating points, cached per 1 mK

    def plan_for(key):
        key = float(key)
        if key not in plans:
            plans[key] = make_plan(build_diagram(dev, key), h, noise_on, scale)
        return plans[key]

    p0 = plan_for(keys[0])
    x = initial_state(p0, scn.settings["initial"]["drive_displacement_m"],
                      from_steady=scn.settings["initial"]["state"] == "steady")
    roll = load_rollout(CARRIER_MODEL, log)
    per_call = max(1, int(round(CALL_S / dt_out)))
    X = np.empty((n, STATE.size))
    est_s = n * M * (110e-9 if roll.compiled else 1e-6) + 0.05 * len(np.unique(np.round(temp, 3)))
    show = progress if progress is not None else est_s > 3.0
    bar = tqdm(total=n, disable=not show, file=sys.stderr, unit="sample", desc=f"carrier {scn.name}",
               mininterval=0.5)
    trim = ref.phase_trim_rad
    any_noise = nz["brownian"] or nz["electronic"]
    for k0 in range(0, n, per_call):
        k1 = min(n, k0 + per_call)
        P = np.empty((k1 - k0, STATE_P))
        uniq, inv = np.unique(keys[k0:k1], return_inverse=True)
        for j, key in enumerate(uniq):
            rows = np.flatnonzero(inv == j)
            ks = rows + k0
            P[rows] = plan_for(key).params(np.deg2rad(rate_dps[ks]), phase_flicker[ks], vref_f[ks], sig["quad_rel"][ks])
        if not any_noise:
            Xc = roll(x, P, np.zeros(((k1 - k0) * M, N_NOISE)), M)
        elif roll.draws_noise:  # the compiled code draws the normals (xoshiro256+ and a ziggurat)
            Xc = roll(x, P, None, M, seed=int(rng.integers(2 ** 63)))
        else:
            Xc = roll(x, P, rng.standard_normal(((k1 - k0) * M, N_NOISE)), M)
        X[k0:k1] = Xc
        x = roll.continue_from(Xc[-1])
        bar.update(k1 - k0)
    bar.close()
    # --- record channels ---------------------------------------------------------------
    lsb = dev.values["noise"]["quantization_lsb_V"] if nz["quantization"] else 0.0
    # the DAQ integrates over each output interval (integrate-and-dump, no aliasing of the white noise)
    rate_V = noisegen.quantize(_state(X, "acc_rate")[:, 0] / M + out_flicker_V + rrw_V, lsb)
    quad_V = noisegen.quantize(_state(X, "acc_quad")[:, 0] / M, lsb)
    ncross, tlast = _state(X, "ncross")[:, 0], _state(X, "tlast")[:, 0]
    freq = np.full(n, np.nan)
    dn = np.diff(ncross)
    dtl = np.diff(tlast)
    ok = (dn > 0) & (dtl > 0)
    freq[1:][ok] = dn[ok] / dtl[ok]
    z = _state(X, "z")
    omega = 2 * np.pi * np.where(np.isfinite(freq), freq, f_ref)
    x_m, v = z[:, 0] * scale[0], z[:, 1] * scale[1]
    amp_m = np.hypot(x_m, v / omega)
    channels = dict(
        time_s=t_end, temperature_C=np.asarray(scn.temperature(t_end), dtype=float),
        rate_dps=rate_V / sf_nom, rate_V=rate_V, rate_true_dps=rate_end, quadrature_V=quad_V,
        drive_amplitude_V=_state(X, "acc_amp")[:, 0] / M, agc_effort_V=_state(X, "acc_u")[:, 0] / M,
        drive_frequency_Hz=freq,
    )
    t_end_die = fx.die_temperature(t_end, np.asarray(scn.temperature(t_end), dtype=float))
    internal = dict(drive_displacement_amplitude_m=amp_m, modulator_norm=_state(X, "n")[:, 0],
                    die_temperature_C=t_end_die)
    wall = time.perf_counter() - wall0
    info = dict(engine="carrier", steps_per_cycle=spc, step_s=h, steps_per_sample=M, output_interval_s=dt_out,
                nominal_scale_factor_V_per_dps=sf_nom, compiled=roll.compiled, compile_s=roll.compile_s,
                wall_time_s=wall, simulated_time_s=float(t_end[-1]), operating_points=len(plans),
                phase_trim_rad=trim)
    meta = {"device": dev.name, "source": "simulation", "engine": "carrier", "scenario": scn.name,
            "seed": str(scn.seed), "nominal_scale_factor_V_per_dps": f"{sf_nom:.9g}"}
    return SimResult(channels, internal, info, meta)
