"""Run scenarios at carrier level: the compiled step rolled out with temperature and rate as inputs.

A run is cut into output samples of ``M`` steps. Each sample has its parameter
vector: the discretised diagram at the sample's die and board temperatures (an
operating point, cached per 1 mK of each and kept across runs of the same device in a
process), the input
rate, and the demodulation-phase flicker. Noise draws come from one seeded
generator per unit in a fixed order, so a seed gives the same record bit for bit.

:func:`run_carrier_units` advances many units (scenarios of the same diagram with
different device values, temperatures, rates or seeds) together, in one compiled
call per chunk vectorised across units; each unit's record is the one
:func:`run_carrier` gives it alone.
"""

from __future__ import annotations

import sys
import time
from collections import OrderedDict

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from ..compiled import load_rollout
from ..effects import EffectSet
from ..result import SimResult, engine_result
from ..scenario import Scenario
from ..slow_noise import draw_slow_noises
from .kits import StepKit, kit_for

#: Temperatures are rounded to this step (K) when caching discretised operating points.
T_QUANTUM_K = 1e-3
#: Simulated seconds per chunk: each chunk's noise comes from its own seed (records depend on it).
CALL_S = 0.02
#: Simulated seconds per compiled call (progress-bar granularity; records do not depend on it).
BATCH_S = 0.5
#: Smallest group of units advanced in vectorised packs (smaller groups run one unit after the other).
MIN_PACKED_UNITS = 3
#: Operating points kept across runs in one process (a few kB each).
PLAN_CACHE_SIZE = 512

_PLANS: OrderedDict = OrderedDict()


def _one_blas_thread():
    """A context pinning the BLAS libraries to one thread (the plans' matrices are 2x2 to 16x16).

    scipy's OpenBLAS otherwise wakes a worker thread for the matrix exponentials, which then
    spins for a while after each call: it doubles the CPU a run takes and gains nothing.
    """
    return threadpool_limits(limits=1, user_api="blas")


class _Unit:
    """One scenario's inputs, operating points, state and generator, prepared for the roll-out."""

    def __init__(self, scn: Scenario, kit: StepKit | None = None):
        self.scn = scn
        self.kit = kit = kit or kit_for(scn.device, "carrier")
        self.wall0 = time.perf_counter()
        dev = self.dev = scn.device
        st = scn.settings["scenario"]
        ref = self.ref = dev.reference_diagram
        self.f_ref = ref.resonator.f_drive_Hz
        self.spc = int(st["steps_per_cycle"])
        h = self.h = kit.step_s(scn, self.f_ref)
        M = self.M = max(1, int(round(1.0 / (st["output_rate_Hz"] * h))))
        self.dt_out = dt_out = M * h
        n = self.n = int(np.ceil(scn.duration_s / dt_out - 1e-9))
        self.t_end = (np.arange(n) + 1) * dt_out
        t_mid = self.t_end - dt_out / 2
        case_mid = np.asarray(scn.temperature(t_mid), dtype=float)
        fx = self.fx = EffectSet(scn.effects)
        temp = fx.die_temperature(t_mid, case_mid)
        board = fx.board_temperature(t_mid, case_mid)
        self.sig = fx.signals(t_mid, temp)
        self.rate_dps = np.asarray(scn.rate(t_mid), dtype=float) + self.sig["rate_dps"]
        self.vref_f = np.asarray(scn.vref_factor(t_mid), dtype=float)
        self.rng = rng = np.random.default_rng(scn.seed)
        nz = scn.noise
        # slow noises, the phase flicker at the output rate
        self.slow = draw_slow_noises(scn, rng, n, dt_out)
        self.noise_on = {"brownian": nz["brownian"], "electronic": nz["electronic"]}
        self.any_noise = nz["brownian"] or nz["electronic"]
        self.scale = ref.core_state_scale()
        # operating points, cached per 1 mK of die and of board temperature
        self.keys = np.round(temp / T_QUANTUM_K) * T_QUANTUM_K
        self.board_keys = np.round(board / T_QUANTUM_K) * T_QUANTUM_K
        self.plans: dict = {}
        self._device_id = dev.content_key
        self.per_call = max(1, int(round(CALL_S / dt_out)))
        p0 = self.plan_for(self.keys[0], self.board_keys[0])
        self.x = kit.initial_state(p0, scn.settings["initial"]["drive_displacement_m"],
                                   from_steady=scn.settings["initial"]["state"] == "steady")
        self.X = np.empty((n, kit.model.state.size))

    def plan_for(self, key, board_key):
        """The operating plan at die temperature ``key`` and board temperature ``board_key`` (both rounded)."""
        key = (float(key), float(board_key))
        if key not in self.plans:
            ck = (self._device_id, key, self.h, tuple(sorted(self.noise_on.items())), self.scale.tobytes())
            plan = _PLANS.get(ck)
            if plan is None:
                with _one_blas_thread():
                    plan = self.kit.make_plan(self.dev, key[0], key[1], self.h, self.noise_on, self.scale)
                _PLANS[ck] = plan
                while len(_PLANS) > PLAN_CACHE_SIZE:
                    _PLANS.popitem(last=False)
            else:
                _PLANS.move_to_end(ck)
            self.plans[key] = plan
        return self.plans[key]

    def operating_points(self, k0: int = 0, k1: int | None = None) -> tuple:
        """The distinct (die, board) keys of samples ``k0 .. k1 - 1`` and each sample's index into them."""
        pairs = np.stack([self.keys[k0:k1], self.board_keys[k0:k1]], axis=1)
        uniq, inv = np.unique(pairs, axis=0, return_inverse=True)
        return uniq, inv.reshape(-1)

    def params(self, k0: int, k1: int) -> np.ndarray:
        """Parameter rows of samples ``k0 .. k1 - 1``."""
        if self.kit.param_rows is not None:
            return self.kit.param_rows(self, k0, k1)
        P = np.empty((k1 - k0, self.kit.model.params.size))
        uniq, inv = self.operating_points(k0, k1)
        for j, (key, board_key) in enumerate(uniq):
            rows = np.flatnonzero(inv == j)
            ks = rows + k0
            P[rows] = self.plan_for(key, board_key).params(np.deg2rad(self.rate_dps[ks]), self.slow.phase_rad[ks],
                                                          self.vref_f[ks], self.sig["quad_rel"][ks])
        return P

    def result(self, roll) -> SimResult:
        """The record channels of the finished roll-out."""
        X, M = self.X, self.M
        outputs, internal = self.kit.channels(X, M, self)
        t_end = self.t_end
        case_end = np.asarray(self.scn.temperature.left_limit(t_end), dtype=float)  # over the sample
        internal["die_temperature_C"] = self.fx.die_temperature(t_end, case_end)
        info = dict(step_s=self.h, output_interval_s=self.dt_out, compiled=roll.compiled, compile_s=roll.compile_s,
                    steps_per_cycle=self.spc, steps_per_sample=M, operating_points=len(self.plans),
                    phase_trim_rad=self.ref.phase_trim_rad)
        return engine_result(self.scn, self.kit.engine, t_end, outputs, self.slow, internal, info, self.wall0)


def _advance(group: list, roll, bar) -> None:
    """Roll a group of units sharing steps per sample, sample count, chunk size and noise mode out together.

    The noise generator of each unit starts from a fresh seed every chunk of ``per_call`` samples (the
    unit's record does not depend on how many chunks one compiled call covers); a call covers about
    :data:`BATCH_S` simulated seconds.
    """
    u0 = group[0]
    n, M, per_call = u0.n, u0.M, u0.per_call
    N_NOISE = u0.kit.model.n_inputs
    for u in group:
        u.roll = roll
    chunks = max(1, int(round((u0.kit.batch_s or BATCH_S) / CALL_S)))
    for k0 in range(0, n, per_call * chunks):
        k1 = min(n, k0 + per_call * chunks)
        P = np.stack([u.params(k0, k1) for u in group])
        x = np.stack([u.x for u in group])
        steps = (k1 - k0) * M
        if not u0.any_noise:
            Xc = roll.units(x, P, np.zeros((len(group), steps, N_NOISE)), M)
        elif roll.draws_noise:  # the compiled code draws the normals (xoshiro256+ and a ziggurat)
            n_chunks = -(-(k1 - k0) // per_call)
            seeds = [[int(u.rng.integers(2 ** 63)) for _ in range(n_chunks)] for u in group]
            Xc = roll.units(x, P, None, M, seeds=seeds, blocks_per_seed=per_call)
        else:
            W = np.stack([np.concatenate([u.rng.standard_normal(((min(k1, c + per_call) - c) * M, N_NOISE))
                                          for c in range(k0, k1, per_call)]) for u in group])
            Xc = roll.units(x, P, W, M)
        for u, Xu in zip(group, Xc):
            u.X[k0:k1] = Xu
            u.x = roll.continue_from(Xu[-1])
        bar.update(len(group) * (k1 - k0))


def run_carrier_units(scns: list[Scenario], progress: bool | None = None, log=None,
                      kit: StepKit | None = None) -> list[SimResult]:
    """Simulate many units at carrier level, advanced together in vectorised compiled calls.

    Units that share the steps per output sample, the number of samples and the noise
    switches run in one call per chunk (a population of one device design with different
    tolerances, temperatures, rates or seeds usually does), in packs of
    :data:`fmvmg_sim.compiled.LANE_WIDTH` lanes vectorised across units; the others in
    further groups. Each unit's record is bit for bit what :func:`run_carrier` gives it alone.

    Parameters
    ----------
    scns : list of Scenario
        One scenario per unit.
    progress : bool, optional
        Show a progress bar on stderr (default: when the runs are expected to take > 3 s).
    log : callable, optional
        One-line messages (default: stderr).
    kit : StepKit, optional
        The step model and its plans (default: the carrier step of each unit's drive topology).

    Returns
    -------
    list of SimResult
        In the order of ``scns``.
    """
    log = log or (lambda m: sys.stderr.write(m + "\n"))
    units = [_Unit(scn, kit) for scn in scns]
    groups: dict = {}
    for u in units:
        groups.setdefault((u.kit.model.name, u.M, u.n, u.per_call, u.any_noise), []).append(u)
    rolls = {g[0].kit.model.name: load_rollout(g[0].kit.model, log) for g in groups.values()}
    roll = next(iter(rolls.values()))
    # a pack of lanes costs about 1.8 units' time: worth it from three units on
    packed = {g[0].kit.model.name: load_rollout(g[0].kit.model, log, lanes=True)
              for g in groups.values() if len(g) >= MIN_PACKED_UNITS}
    total = sum(u.n for u in units)
    per_step_s = (100e-9 if len(units) == 1 else 60e-9) if roll.compiled else 1e-6
    est_s = sum(u.n * u.M for u in units) * per_step_s + 0.04 * sum(
        len(u.operating_points()[0]) for u in units)
    show = progress if progress is not None else est_s > 3.0
    desc = f"{units[0].kit.engine} {scns[0].name}" if len(units) == 1 else f"carrier x{len(units)}"
    bar = tqdm(total=total, disable=not show, file=sys.stderr, unit="sample", desc=desc, mininterval=0.5)
    for group in groups.values():
        name = group[0].kit.model.name
        _advance(group, packed[name] if len(group) >= MIN_PACKED_UNITS else rolls[name], bar)
    bar.close()
    return [u.result(u.roll) for u in units]


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
    return run_carrier_units([scn], progress=progress, log=log)[0]
