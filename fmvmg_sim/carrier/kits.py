"""What the carrier engine's roll-out needs of a step model: its plans, initial state, step and channels.

The roll-out (:mod:`fmvmg_sim.carrier.engine`) advances any step model whose plans give packed
parameter rows per output sample (:class:`fmvmg_sim.carrier.plan.OperatingPlan`). A
:class:`StepKit` names one: the self-oscillating drive's carrier step, the PLL drive's carrier
step, or the PLL drive's envelope step (:mod:`fmvmg_sim.envelope.pll_step`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..compiled import StepModel
from ..diagram import build_diagram
from ..errors import InputError
from .pll_plan import make_pll_plan, pll_initial_state
from .pll_step import PLL_CARRIER_MODEL
from .rebalance import CARRIER_REBALANCE_MODEL, loop_initial_state, loop_plan
from .step import CARRIER_MODEL


@dataclass(frozen=True)
class StepKit:
    """A step model and the functions the roll-out calls around it.

    Attributes
    ----------
    engine : str
        The engine name the record carries (``carrier`` or ``envelope``).
    model : StepModel
    make_plan : callable
        ``(device, die_C, board_C, h_s, noise_on, scale) -> OperatingPlan``.
    initial_state : callable
        ``(plan, drive_displacement_m, from_steady) -> state``.
    step_s : callable
        ``(scenario, f_ref_Hz) -> step length``.
    channels : callable
        ``(X, M, unit) -> (outputs, internal)``: record channels from the states at the output samples.
    param_rows : callable, optional
        ``(unit, k0, k1) -> rows``: the parameter rows of samples ``k0 .. k1 - 1``, when the kit makes
        them itself (default: from one plan per operating point).
    batch_s : float, optional
        Simulated seconds per compiled call (default: the engine's ``BATCH_S``); records do not depend on it.
    """

    engine: str
    model: StepModel
    make_plan: Callable
    initial_state: Callable
    step_s: Callable
    channels: Callable
    param_rows: Callable | None = None
    batch_s: float | None = None


def _cycle_step(scn, f_ref_Hz: float) -> float:
    return 1.0 / (int(scn.settings["scenario"]["steps_per_cycle"]) * f_ref_Hz)


def _field(X, layout, name):
    return X[:, layout.slices[name]]


def _self_oscillating_channels(X, M, unit) -> tuple[dict, dict]:
    L = CARRIER_MODEL.state
    n = X.shape[0]
    ncross, tlast = _field(X, L, "ncross")[:, 0], _field(X, L, "tlast")[:, 0]
    freq = np.full(n, np.nan)
    dn = np.diff(ncross)
    dtl = np.diff(tlast)
    ok = (dn > 0) & (dtl > 0)
    freq[1:][ok] = dn[ok] / dtl[ok]
    z = _field(X, L, "z")
    omega = 2 * np.pi * np.where(np.isfinite(freq), freq, unit.f_ref)
    x_m, v = z[:, 0] * unit.scale[0], z[:, 1] * unit.scale[1]
    # the DAQ integrates over each output interval (integrate-and-dump, no aliasing of the white noise)
    outputs = dict(rate_V=_field(X, L, "acc_rate")[:, 0] / M, quadrature_V=_field(X, L, "acc_quad")[:, 0] / M,
                   drive_amplitude_V=_field(X, L, "acc_amp")[:, 0] / M, agc_effort_V=_field(X, L, "acc_u")[:, 0] / M,
                   drive_frequency_Hz=freq)
    internal = dict(drive_displacement_amplitude_m=np.hypot(x_m, v / omega), modulator_norm=_field(X, L, "n")[:, 0])
    return outputs, internal


def pll_channels(X, M, unit, layout, displacement) -> tuple[dict, dict]:
    """Record channels of a PLL drive's step (carrier or envelope): outputs and internal signals.

    Parameters
    ----------
    X : ndarray
        States at the output samples.
    M : int
        Steps per output sample.
    unit : object
        The roll-out's unit (its ``scale`` and ``f_ref``).
    layout : Layout
        The step model's state layout.
    displacement : callable
        ``(X, unit) -> drive displacement amplitude (m)``.

    Returns
    -------
    tuple of dict
    """
    def mean(name):
        return _field(X, layout, name)[:, 0] / M

    outputs = dict(rate_V=mean("acc_rate"), quadrature_V=mean("acc_quad"), drive_amplitude_V=mean("acc_amp"),
                   agc_effort_V=mean("acc_u"), drive_frequency_Hz=mean("acc_f"))
    internal = dict(drive_displacement_amplitude_m=displacement(X, unit), pll_tuning_V=mean("acc_tune"))
    return outputs, internal


def _pll_carrier_displacement(X, unit):
    z = _field(X, PLL_CARRIER_MODEL.state, "z")
    f = _field(X, PLL_CARRIER_MODEL.state, "acc_f")[:, 0] / unit.M
    return np.hypot(z[:, 0] * unit.scale[0], z[:, 1] * unit.scale[1] / (2 * np.pi * f))


def _pll_plan(device, die_C, board_C, h_s, noise_on, scale):
    from ..pll_drive import build_pll_drive
    return make_pll_plan(build_pll_drive(device, die_C, board_C), h_s, noise_on, scale)


def _self_oscillating_plan(dev, die, board, h, noise_on, scale):
    return loop_plan(build_diagram(dev, die, board_C=board), h, noise_on, scale)


SELF_OSCILLATING_CARRIER = StepKit(
    "carrier", CARRIER_MODEL, _self_oscillating_plan, loop_initial_state, _cycle_step, _self_oscillating_channels)

#: The self-oscillating drive with a closed sense loop (force-to-rebalance, quadrature control): the carrier
#: step extended by the loops' states (its state layout starts with the open chain's).
CLOSED_SENSE_CARRIER = StepKit(
    "carrier", CARRIER_REBALANCE_MODEL, _self_oscillating_plan, loop_initial_state, _cycle_step,
    _self_oscillating_channels)

PLL_CARRIER = StepKit(
    "carrier", PLL_CARRIER_MODEL, _pll_plan, pll_initial_state, _cycle_step,
    lambda X, M, unit: pll_channels(X, M, unit, PLL_CARRIER_MODEL.state, _pll_carrier_displacement))


def kit_for(device, engine: str = "carrier") -> StepKit:
    """The step kit of ``device``'s drive topology for ``engine``.

    Parameters
    ----------
    device : Device
    engine : {"carrier", "envelope"}
        ``envelope`` only for the PLL drive (the self-oscillating drive's envelope engine is its own).

    Returns
    -------
    StepKit
    """
    closed_sense = device.reference_diagram.sense_loop is not None
    if device.drive_topology == "pll":
        if closed_sense:
            raise InputError("a closed sense loop (force-to-rebalance or quadrature control) runs with the "
                             "self-oscillating drive only", "circuit.drive.topology")
        if engine == "envelope":
            from ..envelope.pll_plan import PLL_ENVELOPE
            return PLL_ENVELOPE
        return PLL_CARRIER
    return CLOSED_SENSE_CARRIER if closed_sense else SELF_OSCILLATING_CARRIER


__all__ = ["StepKit", "kit_for", "pll_channels", "SELF_OSCILLATING_CARRIER", "CLOSED_SENSE_CARRIER", "PLL_CARRIER"]
