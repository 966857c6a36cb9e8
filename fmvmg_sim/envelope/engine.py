"""Run a scenario with the averaged model: hours of oven time in seconds.

The run is cut into parameter blocks of about a second; each block gets the averaged
model discretised at its temperature, interpolated (cubic) from operating points on a
5 K grid over the temperatures the scenario visits. Per-step inputs are the noise
draws, the rate, the set-point factor and the demodulation-phase flicker.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy.interpolate import CubicSpline
from tqdm import tqdm

from .. import noise as noisegen
from ..averaged import scale_factor_V_per_dps
from ..compiled import load_rollout
from ..diagram import build_diagram
from ..effects import EffectSet
from ..result import SimResult
from ..scenario import Scenario
from ..carrier.discretize import batched_factor
from .model import IA, IS1, PARAMS, N, operating_params
from .step import ENVELOPE_MODEL, N_IN, STATE

#: Spacing of the temperature grid on which the averaged model is discretised (K).
T_GRID_K = 5.0
#: Largest spacing of the board-minus-die offset grid (K): the electronics move the parameters by a few
#: per cent over it, so a quadratic through three nodes is accurate to about 1e-7.
OFFSET_GRID_K = 10.0
#: Target length of a parameter block (s).
BLOCK_S = 1.0
#: Simulated seconds per compiled call.
CALL_S = 600.0


class _ParamTable:
    """Packed parameter vectors of the averaged model as a smooth function of die and board temperature.

    A cubic spline in the die temperature on a :data:`T_GRID_K` grid; when the board does not follow the
    die (thermal lag), a tensor-product spline with the board-minus-die offset on a grid of at least three
    nodes, at most :data:`OFFSET_GRID_K` apart, spanning the offsets the run visits.
    """

    def __init__(self, device, h_s, noise_on, t_lo, t_hi, off_lo=0.0, off_hi=0.0):
        if t_hi - t_lo < 1e-6:
            grid = np.array([t_lo])
        else:
            n = max(4, int(np.ceil((t_hi - t_lo) / T_GRID_K)) + 3)
            grid = np.linspace(t_lo - T_GRID_K, t_hi + T_GRID_K, n)
        self.grid = grid
        if off_hi - off_lo < 1e-6:
            self.offsets = np.array([0.5 * (off_lo + off_hi)])
        else:
            self.offsets = np.linspace(off_lo, off_hi, max(3, int(np.ceil((off_hi - off_lo) / OFFSET_GRID_K)) + 1))
        tables, covs, self.extra = [], [], []
        for T in grid:
            ops = [operating_params(build_diagram(device, float(T), board_C=float(T + o)), h_s, noise_on)
                   for o in self.offsets]
            tables.append([PARAMS.pack(op) for op in ops])
            covs.append([op["Q"] for op in ops])
            self.extra.append(ops)
        self.table = np.array(tables)  # (die, offset, param)
        self.cov = np.array(covs)
        self.spline = CubicSpline(grid, self.table, axis=0) if len(grid) > 1 else None
        self.cov_spline = CubicSpline(grid, self.cov, axis=0) if len(grid) > 1 else None
        self.off_weights = CubicSpline(self.offsets, np.eye(len(self.offsets)), axis=0) \
            if len(self.offsets) > 1 else None

    def nearest(self, T: float, offset: float = 0.0) -> dict:
        """The averaged model's operating parameters at the grid node nearest ``T`` and ``offset``."""
        return self.extra[int(np.argmin(np.abs(self.grid - T)))][int(np.argmin(np.abs(self.offsets - offset)))]

    def _at(self, T: np.ndarray) -> tuple:
        """Table and covariance at die temperatures ``T``, at every offset node."""
        if self.spline is None:
            return np.repeat(self.table, len(T), axis=0), np.repeat(self.cov, len(T), axis=0)
        return self.spline(T), self.cov_spline(T)

    def __call__(self, T: np.ndarray, offset: np.ndarray | float = 0.0) -> np.ndarray:
        """Packed parameters at each die temperature ``T`` and board-minus-die ``offset``; the noise factor is
        taken from the interpolated covariance (covariances are smooth in T, their triangular factors need not be)."""
        T = np.atleast_1d(T)
        L = PARAMS.slices["L"]
        if self.off_weights is None and self.spline is None:
            return np.repeat(self.table[:, 0], len(T), axis=0)
        if self.off_weights is None:  # the board follows the die at a fixed offset
            P, cov = (x[:, 0] for x in self._at(T))
            P[:, L] = batched_factor(cov).reshape(len(T), -1)
            return P
        W = self.off_weights(np.broadcast_to(np.asarray(offset, dtype=float), T.shape))
        P = np.empty((len(T), self.table.shape[-1]))
        for r0 in range(0, len(T), 4096):  # in chunks of rows: the (rows, offsets, params) values stay small
            r = slice(r0, r0 + 4096)
            tab, cov = self._at(T[r])
            P[r] = np.einsum("ko,kop->kp", W[r], tab)
            P[r, L] = batched_factor(np.einsum("ko,koij->kij", W[r], cov)).reshape(len(tab), -1)
        return P


def run_envelope(scn: Scenario, progress: bool | None = None, log=None) -> SimResult:
    """Simulate ``scn`` with the averaged (envelope) model.

    Parameters
    ----------
    scn : Scenario
    progress : bool, optional
        Progress bar on stderr (default: when the run is expected to take > 3 s).
    log : callable, optional

    Returns
    -------
    SimResult
    """
    log = log or (lambda m: sys.stderr.write(m + "\n"))
    wall0 = time.perf_counter()
    dev = scn.device
    st = scn.settings["scenario"]
    dt_out = 1.0 / st["output_rate_Hz"]
    Mo = max(1, int(np.ceil(dt_out / st["envelope_step_s"] - 1e-9)))
    h = dt_out / Mo
    n_out = int(np.ceil(scn.duration_s / dt_out - 1e-9))
    nob = max(1, min(n_out, int(round(BLOCK_S / dt_out))))
    K = int(np.ceil(n_out / nob))
    n_out_pad = K * nob
    t_out = (np.arange(n_out_pad) + 1) * dt_out
    t_step = (np.arange(n_out_pad * Mo) + 1) * h
    t_blk = (np.arange(K) + 0.5) * nob * dt_out
    fx = EffectSet(scn.effects)
    # die temperature (thermal lag) and board temperature (the case) on a fine grid, then at the blocks
    t_fine = np.linspace(0.0, t_out[-1], max(2, min(len(t_out), 200000)))
    case_fine = np.asarray(scn.temperature(t_fine), dtype=float)
    die_fine = fx.die_temperature(t_fine, case_fine)
    temp_blk = np.interp(t_blk, t_fine, die_fine)
    off_blk = np.interp(t_blk, t_fine, fx.board_temperature(t_fine, case_fine) - die_fine)
    temp_all = np.interp(t_out, t_fine, die_fine)
    sig_fine = fx.signals(t_fine, die_fine)
    nz = scn.noise
    noise_on = {"brownian": nz["brownian"], "electronic": nz["electronic"]}
    tab = _ParamTable(dev, h, noise_on, float(min(temp_blk.min(), temp_all.min())),
                      float(max(temp_blk.max(), temp_all.max())), float(off_blk.min()), float(off_blk.max()))
    P_all = tab(temp_blk, off_blk)
    rng = np.random.default_rng(scn.seed)
    n_steps = len(t_step)
    phase = (noisegen.flicker(n_steps, 1.0 / h, dev.values["noise"]["flicker_phase_rad2"], rng)
             if nz["flicker"] else np.zeros(n_steps))
    sf_nom = scale_factor_V_per_dps(build_diagram(scn.device_nominal, dev.reference_temperature_C))
    out_flicker_V = (noisegen.flicker(n_out_pad, 1.0 / dt_out, dev.values["noise"]["flicker_output_dps2"], rng)
                     * sf_nom if nz["flicker"] else np.zeros(n_out_pad))
    rrw_V = (noisegen.random_walk(n_out_pad, 1.0 / dt_out, dev.values["noise"]["rate_random_walk_dps_per_sqrt_s"],
                                  rng) * sf_nom if nz["rate_random_walk"] else np.zeros(n_out_pad))
    rate_step = np.deg2rad(np.asarray(scn.rate(t_step), dtype=float) + np.interp(t_step, t_fine, sig_fine["rate_dps"]))
    quad_step = np.interp(t_step, t_fine, sig_fine["quad_rel"])
    fac_step = np.asarray(scn.vref_factor(t_step), dtype=float)
    x = _initial(scn, tab, temp_blk[0], off_blk[0])
    roll = load_rollout(ENVELOPE_MODEL, log)
    any_noise = nz["brownian"] or nz["electronic"]
    blocks_per_call = max(1, int(round(CALL_S / (nob * dt_out))))
    X = np.empty((n_out_pad, STATE.size))
    show = progress if progress is not None else n_steps > 3e6
    bar = tqdm(total=K, disable=not show, file=sys.stderr, unit="block", desc=f"envelope {scn.name}",
               mininterval=0.5)
    steps_blk = nob * Mo
    for k0 in range(0, K, blocks_per_call):
        k1 = min(K, k0 + blocks_per_call)
        s0, s1 = k0 * steps_blk, k1 * steps_blk
        W = np.empty((s1 - s0, N_IN))
        nn = N_IN - 4
        # float32 draws: half the cost of float64, and far finer than any noise level here
        W[:, :nn] = rng.standard_normal((s1 - s0, nn), dtype=np.float32) if any_noise else 0.0
        W[:, nn] = rate_step[s0:s1]
        W[:, nn + 1] = fac_step[s0:s1]
        W[:, nn + 2] = phase[s0:s1]
        W[:, nn + 3] = quad_step[s0:s1]
        Xc = roll(x, P_all[k0:k1], W, Mo, nob)
        X[k0 * nob:k1 * nob] = Xc
        x = roll.continue_from(Xc[-1])
        bar.update(k1 - k0)
    bar.close()
    X, t_out = X[:n_out], t_out[:n_out]
    out_flicker_V, rrw_V = out_flicker_V[:n_out], rrw_V[:n_out]
    get = lambda name: X[:, STATE.slices[name]]  # noqa: E731
    lsb = dev.values["noise"]["quantization_lsb_V"] if nz["quantization"] else 0.0
    rate_V = noisegen.quantize(get("rate_V")[:, 0] + out_flicker_V + rrw_V, lsb)
    quad_V = noisegen.quantize(get("quad_V")[:, 0], lsb)
    channels = dict(
        time_s=t_out, temperature_C=np.asarray(scn.temperature(t_out), dtype=float),
        rate_dps=rate_V / sf_nom, rate_V=rate_V, rate_true_dps=np.asarray(scn.rate(t_out), dtype=float),
        quadrature_V=quad_V, drive_amplitude_V=get("amp_V")[:, 0], agc_effort_V=get("agc_V")[:, 0],
        drive_frequency_Hz=get("freq_Hz")[:, 0],
    )
    internal = dict(drive_displacement_amplitude_m=get("x")[:, 0], die_temperature_C=temp_all[:n_out])
    wall = time.perf_counter() - wall0
    info = dict(engine="envelope", step_s=h, steps_per_output=Mo, output_interval_s=dt_out,
                nominal_scale_factor_V_per_dps=sf_nom, compiled=roll.compiled, compile_s=roll.compile_s,
                wall_time_s=wall, simulated_time_s=float(t_out[-1]), temperature_grid_points=len(tab.grid),
                board_offset_grid_points=len(tab.offsets),
                steps_per_cycle=None)
    meta = {"device": dev.name, "source": "simulation", "engine": "envelope", "scenario": scn.name,
            "seed": str(scn.seed), "nominal_scale_factor_V_per_dps": f"{sf_nom:.9g}"}
    return SimResult(channels, internal, info, meta)


def _initial(scn: Scenario, tab: _ParamTable, T0: float, offset0: float = 0.0) -> np.ndarray:
    """Initial envelope state: at rest with the initial displacement, or on the averaged steady state."""
    op = tab.nearest(T0, offset0)
    ss = op["steady"]
    x = dict(x=np.zeros(N), u=0.0, w_rate=np.deg2rad(float(scn.rate(0.0))), vref_f=float(scn.vref_factor(0.0)), dkq=0.0,
             acc_t=0.0, acc_u=0.0, rate_V=0.0, quad_V=0.0, amp_V=0.0, agc_V=0.0, freq_Hz=ss.f_Hz)
    if scn.settings["initial"]["state"] == "steady":
        x["x"] = op["x_steady"].copy()
        x["x"][IS1] = op["vref0"] * x["vref_f"]
        x["u"] = ss.agc_effort_V
        x["rate_V"], x["quad_V"] = ss.rate_V, ss.quadrature_V
    else:
        x["x"][IA] = scn.settings["initial"]["drive_displacement_m"]
    return STATE.pack(x)
