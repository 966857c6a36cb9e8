"""Run a scenario with the averaged model: hours of oven time in seconds.

The run is cut into parameter blocks of about a second, ended at every jump of the temperature
profile and shortened where the temperature moves fast (:func:`parameter_blocks`); each block gets
the averaged model discretised at its mean die temperature (and, under a thermal lag, the mean offset of
the board, which stays on the case), interpolated (cubic) from operating points on a 5 K grid over the
temperatures the scenario visits. Per-step inputs are the noise
draws, the rate, set-point factor and quadrature change as the start and end values of their
first-order hold over the step (so a profile's steps and ramps enter at their times), and the
demodulation-phase flicker.
"""

from __future__ import annotations

import sys
import time

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline
from tqdm import tqdm

from ..compiled import load_rollout
from ..diagram import build_diagram
from ..effects import EffectSet
from ..numerics.layout import Layout
from ..result import SimResult, engine_result
from ..scenario import Scenario
from ..slow_noise import draw_slow_noises
from . import rebalance
from .model import IA, PARAMS, N, noise_factor, operating_params, steady_vector
from .step import ENVELOPE_MODEL, INPUTS, STATE

#: Spacing of the temperature grid on which the averaged model is discretised (K).
T_GRID_K = 5.0
#: Largest spacing of the board-minus-die offset grid (K): the electronics move the parameters by a few
#: per cent over it, so a quadratic through three nodes is accurate to about 1e-7.
OFFSET_GRID_K = 10.0
#: Target length of a parameter block (s).
BLOCK_S = 1.0
#: Largest die-temperature change within one parameter block (K); faster changes get shorter blocks.
BLOCK_SPAN_K = 0.2
#: Simulated seconds per compiled call.
CALL_S = 600.0


@dataclass(frozen=True)
class _Kit:
    """The averaged model a device runs in: the open sense chain's, or with its closed sense loops."""

    operating_params: Callable
    params: Layout
    noise_factor: Callable
    steady_vector: Callable
    model: object
    state: Layout
    inputs: Layout
    n: int


_OPEN = _Kit(operating_params, PARAMS, noise_factor, steady_vector, ENVELOPE_MODEL, STATE, INPUTS, N)
_LOOPS = _Kit(rebalance.operating_params, rebalance.PARAMS_R, rebalance.noise_factor, rebalance.steady_vector,
              rebalance.ENVELOPE_REBALANCE_MODEL, rebalance.REBALANCE_STEP.state, rebalance.REBALANCE_STEP.inputs,
              rebalance.N_R)


def _kit(device) -> _Kit:
    return _OPEN if device.reference_diagram.sense_loop is None else _LOOPS


class _ParamTable:
    """Packed parameter vectors of the averaged model as a smooth function of die and board temperature.

    A cubic spline in the die temperature on a :data:`T_GRID_K` grid; when the board does not follow the
    die (thermal lag), a tensor-product spline with the board-minus-die offset on a grid of at least three
    nodes, at most :data:`OFFSET_GRID_K` apart, spanning the offsets the run visits.
    """

    def __init__(self, device, h_s, noise_on, t_lo, t_hi, off_lo=0.0, off_hi=0.0, kit=_OPEN):
        self.kit = kit
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
        tables, covs = [], []
        for T in grid:
            ops = [kit.operating_params(build_diagram(device, float(T), board_C=float(T + o)), h_s, noise_on)
                   for o in self.offsets]
            tables.append([kit.params.pack(op) for op in ops])
            covs.append([op["Q"] for op in ops])
        self.table = np.array(tables)  # (die, offset, param)
        self.cov = np.array(covs)
        self.spline = CubicSpline(grid, self.table, axis=0) if len(grid) > 1 else None
        self.cov_spline = CubicSpline(grid, self.cov, axis=0) if len(grid) > 1 else None
        self.off_weights = CubicSpline(self.offsets, np.eye(len(self.offsets)), axis=0) \
            if len(self.offsets) > 1 else None

    def _at(self, T: np.ndarray) -> tuple:
        """Table and covariance at die temperatures ``T``, at every offset node."""
        if self.spline is None:
            return np.repeat(self.table, len(T), axis=0), np.repeat(self.cov, len(T), axis=0)
        return self.spline(T), self.cov_spline(T)

    def __call__(self, T: np.ndarray, offset: np.ndarray | float = 0.0) -> np.ndarray:
        """Packed parameters at each die temperature ``T`` and board-minus-die ``offset``; the noise factor is
        taken from the interpolated covariance (covariances are smooth in T, their triangular factors need not be)."""
        T = np.atleast_1d(np.asarray(T, dtype=float))
        offset = np.broadcast_to(np.asarray(offset, dtype=float), T.shape)
        # a run's blocks repeat their temperatures (holds): each distinct (die, offset) pair is evaluated once
        pairs, inverse = np.unique(np.stack([T, offset], axis=1), axis=0, return_inverse=True)
        if len(pairs) < len(T):
            return self(pairs[:, 0], pairs[:, 1])[inverse.reshape(-1)]
        L = self.kit.params.slices["L"]
        noise_factor = self.kit.noise_factor
        if self.off_weights is None and self.spline is None:
            return np.repeat(self.table[:, 0], len(T), axis=0)
        if self.off_weights is None:  # the board follows the die at a fixed offset
            P, cov = (x[:, 0] for x in self._at(T))
            P[:, L] = noise_factor(cov).reshape(len(T), -1)
            return P
        W = self.off_weights(offset)
        P = np.empty((len(T), self.table.shape[-1]))
        for r0 in range(0, len(T), 4096):  # in chunks of rows: the (rows, offsets, params) values stay small
            r = slice(r0, r0 + 4096)
            tab, cov = self._at(T[r])
            P[r] = np.einsum("ko,kop->kp", W[r], tab)
            P[r, L] = noise_factor(np.einsum("ko,koij->kij", W[r], cov)).reshape(len(tab), -1)
        return P


def parameter_blocks(scn: Scenario, fx: EffectSet, dt_out: float, n_out: int, t_fine: np.ndarray,
                     die_fine: np.ndarray) -> tuple[list, np.ndarray]:
    """Parameter blocks of a run and the die temperature each is discretised at.

    Blocks are about :data:`BLOCK_S` long, end at every jump of the temperature profile (at the
    start of the output sample it falls in, the first whose record shows the new temperature)
    and are cut shorter where the die temperature would move more than
    :data:`BLOCK_SPAN_K` within one. Each block's temperature is the mean of the die temperature
    over it.

    Parameters
    ----------
    scn : Scenario
    fx : EffectSet
    dt_out : float
        Output interval (s).
    n_out : int
        Output samples.
    t_fine, die_fine : ndarray
        The die temperature on a fine time grid (thermal lag applied).

    Returns
    -------
    tuple
        ``[(first output, outputs), ...]`` and the block temperatures (degC).
    """
    nob = max(1, min(n_out, int(round(BLOCK_S / dt_out))))
    cuts = set(range(0, n_out, nob))
    # a jump enters with the sample it falls in: the record's temperature_C, the value over each sample (the
    # left limit at its end), shows it there
    cuts.update(int(c) for c in np.floor(scn.temperature.jumps_s() / dt_out + 1e-9) if 0 < c < n_out)
    edges = np.array(sorted(cuts) + [n_out])
    lag = bool(fx.get("thermal_lag"))
    if lag:  # the die temperature's integral on the fine grid, read at the block edges
        cum = np.concatenate(([0.0], np.cumsum(np.diff(t_fine) * 0.5 * (die_fine[1:] + die_fine[:-1]))))
        mean_of = lambda te: np.diff(np.interp(te, t_fine, cum)) / np.diff(te)  # noqa: E731
        pts_t, pts_T = t_fine, die_fine
    else:  # no lag: the die follows the profile, whose means over any interval are exact
        mean_of = lambda te: np.mean(scn.temperature.step_lines(te), axis=0)  # noqa: E731
        prof = scn.temperature
        jump = np.isin(prof.times_s, prof.jumps_s())  # a jump is an edge of its own (above)
        pts_t, pts_T = prof.times_s[~jump], prof.values[~jump]
    # the extremes over a block are at its edges or at the points inside it (piecewise linear between)
    te = edges * dt_out
    if lag:
        at_start, at_end = np.interp(te[:-1], t_fine, die_fine), np.interp(te[1:], t_fine, die_fine)
    else:
        at_start, at_end = scn.temperature(te[:-1]), scn.temperature.left_limit(te[1:])
    hi, lo = np.maximum(at_start, at_end), np.minimum(at_start, at_end)
    inside = (pts_t > te[0]) & (pts_t < te[-1])
    k = np.searchsorted(te, pts_t[inside], side="right") - 1
    np.maximum.at(hi, k, pts_T[inside])
    np.minimum.at(lo, k, pts_T[inside])
    # blocks whose temperature spans more than BLOCK_SPAN_K (fast ramps) are cut where the temperature has
    # moved by BLOCK_SPAN_K along them (at output samples)
    split = (hi - lo) > BLOCK_SPAN_K
    blocks = []
    for a, b, cut in zip(edges[:-1], edges[1:], split):
        if not cut:
            blocks.append((int(a), int(b - a)))
            continue
        tk = np.arange(a, b + 1) * dt_out
        Tk = np.interp(tk, t_fine, die_fine) if lag else np.asarray(scn.temperature(tk), dtype=float)
        if not lag:
            Tk[-1] = scn.temperature.left_limit(tk[-1])
        moved = np.concatenate(([0.0], np.cumsum(np.abs(np.diff(Tk)))))
        # the sample in which the movement passes a multiple of BLOCK_SPAN_K is a block of its own
        marks = np.unique(np.floor(moved / BLOCK_SPAN_K + 1e-9).astype(int), return_index=True)[1][1:]
        starts = np.unique(np.concatenate(([0], marks - 1, marks)))
        starts = starts[starts < b - a]
        ends = np.concatenate((starts[1:], [b - a]))
        blocks += [(int(a + s0), int(s1 - s0)) for s0, s1 in zip(starts, ends)]
    te = np.array([blk[0] for blk in blocks] + [n_out]) * dt_out
    return blocks, np.asarray(mean_of(te), dtype=float)


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
    if scn.device.drive_topology == "pll":  # the PLL drive's envelope step, through the step-kit roll-out
        from ..carrier.engine import run_carrier_units
        from ..carrier.kits import kit_for
        return run_carrier_units([scn], progress=progress, log=log, kit=kit_for(scn.device, "envelope"))[0]
    log = log or (lambda m: sys.stderr.write(m + "\n"))
    wall0 = time.perf_counter()
    dev = scn.device
    st = scn.settings["scenario"]
    dt_out = 1.0 / st["output_rate_Hz"]
    Mo = max(1, int(np.ceil(dt_out / st["envelope_step_s"] - 1e-9)))
    h = dt_out / Mo
    n_out = int(np.ceil(scn.duration_s / dt_out - 1e-9))
    t_out = (np.arange(n_out) + 1) * dt_out
    fx = EffectSet(scn.effects)
    # die temperature (thermal lag) and board temperature (the case) on a fine grid, then at the blocks
    t_fine = np.linspace(0.0, t_out[-1], max(2, min(len(t_out), 200000)))
    case_fine = np.asarray(scn.temperature(t_fine), dtype=float)
    die_fine = fx.die_temperature(t_fine, case_fine)
    blocks, temp_blk = parameter_blocks(scn, fx, dt_out, n_out, t_fine, die_fine)
    off_blk = _block_means(blocks, dt_out, t_fine, fx.board_temperature(t_fine, case_fine) - die_fine) \
        if fx.get("thermal_lag") else np.zeros(len(blocks))
    case_out = np.asarray(scn.temperature.left_limit(t_out), dtype=float)  # over each sample
    temp_all = np.interp(t_out, t_fine, die_fine) if fx.get("thermal_lag") else case_out
    sig_fine = fx.signals(t_fine, die_fine)
    nz = scn.noise
    noise_on = {"brownian": nz["brownian"], "electronic": nz["electronic"]}
    kit = _kit(dev)
    tab = _ParamTable(dev, h, noise_on, float(min(temp_blk.min(), temp_all.min())),
                      float(max(temp_blk.max(), temp_all.max())), float(off_blk.min()), float(off_blk.max()), kit)
    rng = np.random.default_rng(scn.seed)
    n_steps = n_out * Mo
    slow = draw_slow_noises(scn, rng, n_out, dt_out)  # the phase flicker held over each output interval
    x = _initial(scn, float(temp_blk[0]), float(off_blk[0]), kit)
    roll = load_rollout(kit.model, log)
    any_noise = nz["brownian"] or nz["electronic"]
    X = np.empty((n_out, kit.state.size))
    show = progress if progress is not None else n_steps > 3e6
    bar = tqdm(total=n_out, disable=not show, file=sys.stderr, unit="sample", desc=f"envelope {scn.name}",
               mininterval=0.5)
    for k0, k1 in _calls(blocks, int(round(CALL_S / dt_out))):
        o0, nob = blocks[k0]
        o1 = blocks[k1 - 1][0] + nob
        s0, s1 = o0 * Mo, o1 * Mo
        W = _inputs(kit, scn, rng, any_noise, (s0 + np.arange(s1 - s0 + 1)) * h, t_fine, sig_fine,
                    np.repeat(slow.phase_rad[o0:o1], Mo))
        Xc = roll(x, tab(temp_blk[k0:k1], off_blk[k0:k1]), W, Mo, nob)
        X[o0:o1] = Xc
        x = roll.continue_from(Xc[-1])
        bar.update(o1 - o0)
    bar.close()
    get = lambda name: X[:, kit.state.slices[name]][:, 0]  # noqa: E731
    outputs = dict(rate_V=get("rate_V"), quadrature_V=get("quad_V"), drive_amplitude_V=get("amp_V"),
                   agc_effort_V=get("agc_V"), drive_frequency_Hz=get("freq_Hz"))
    internal = dict(drive_displacement_amplitude_m=get("x"), die_temperature_C=temp_all)
    info = dict(step_s=h, output_interval_s=dt_out, compiled=roll.compiled, compile_s=roll.compile_s,
                steps_per_cycle=None, steps_per_output=Mo, temperature_grid_points=len(tab.grid),
                parameter_blocks=len(blocks), board_offset_grid_points=len(tab.offsets))
    return engine_result(scn, "envelope", t_out, outputs, slow, internal, info, wall0)


def _block_means(blocks: list, dt_out: float, t_fine: np.ndarray, y_fine: np.ndarray) -> np.ndarray:
    """Mean of ``y_fine`` (on ``t_fine``, linear between) over each parameter block."""
    cum = np.concatenate(([0.0], np.cumsum(np.diff(t_fine) * 0.5 * (y_fine[1:] + y_fine[:-1]))))
    te = np.array([b[0] for b in blocks] + [blocks[-1][0] + blocks[-1][1]]) * dt_out
    return np.diff(np.interp(te, t_fine, cum)) / np.diff(te)


def _calls(blocks: list, max_outputs: int):
    """Ranges ``[k0, k1)`` of blocks for one compiled call each: equal block lengths, at most
    ``max_outputs`` outputs (and at least one block) per call."""
    k0 = 0
    while k0 < len(blocks):
        nob = blocks[k0][1]
        k1 = k0 + 1
        while k1 < len(blocks) and blocks[k1][1] == nob and (k1 + 1 - k0) * nob <= max_outputs:
            k1 += 1
        yield k0, k1
        k0 = k1


def _inputs(kit: _Kit, scn: Scenario, rng, any_noise: bool, t_edges: np.ndarray, t_fine: np.ndarray, sig_fine: dict,
            phase: np.ndarray) -> np.ndarray:
    """Per-step inputs (:data:`~fmvmg_sim.envelope.step.INPUTS`) of the steps between ``t_edges``."""
    n = len(t_edges) - 1
    n_noise = kit.inputs.shapes["noise"][0]
    W = np.empty((n, kit.inputs.size))
    col = {name: sl.start for name, sl in kit.inputs.slices.items()}
    # float32 draws: half the cost of float64, and far finer than any noise level here
    W[:, :n_noise] = rng.standard_normal((n, n_noise), dtype=np.float32) if any_noise else 0.0
    for name, profile in (("rate", scn.rate), ("vref_f", scn.vref_factor)):
        W[:, col[name]], W[:, col[name] + 1] = profile.step_lines(t_edges)
    W[:, col["rate"]:col["rate"] + 2] *= np.pi / 180.0
    if np.any(sig_fine["rate_dps"]):
        extra = np.deg2rad(np.interp(t_edges, t_fine, sig_fine["rate_dps"]))
        W[:, col["rate"]] += extra[:-1]
        W[:, col["rate"] + 1] += extra[1:]
    if np.any(sig_fine["quad_rel"]):
        q = np.interp(t_edges, t_fine, sig_fine["quad_rel"])
        W[:, col["quad_rel"]], W[:, col["quad_rel"] + 1] = q[:-1], q[1:]
    else:
        W[:, col["quad_rel"]:col["quad_rel"] + 2] = 0.0
    W[:, col["phase"]] = phase
    return W


def _initial(scn: Scenario, T0: float, offset0: float = 0.0, kit: _Kit = _OPEN) -> np.ndarray:
    """Initial envelope state: at rest with the initial displacement, or on the averaged steady state at the die
    temperature ``T0`` with the board ``offset0`` above it."""
    dg = build_diagram(scn.device, T0, board_C=T0 + offset0)
    x = dict(x=np.zeros(kit.n), u=0.0, acc_t=0.0, acc_u=0.0, rate_V=0.0, quad_V=0.0, amp_V=0.0, agc_V=0.0,
             freq_Hz=dg.resonator.f_drive_Hz, refine=0.0)
    if scn.settings["initial"]["state"] == "steady":
        x["x"], ss = kit.steady_vector(dg, np.deg2rad(float(scn.rate(0.0))), float(scn.vref_factor(0.0)))
        x["u"], x["freq_Hz"] = ss.agc_effort_V, ss.f_Hz
        x["rate_V"], x["quad_V"] = ss.rate_V, ss.quadrature_V
    else:
        x["x"][IA] = scn.settings["initial"]["drive_displacement_m"]
    return kit.state.pack(x)
