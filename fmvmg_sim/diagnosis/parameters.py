"""Knobs: named scalar parameters that act on a device, for calibration and attribution.

A *nominal* knob is a unit-to-unit tolerance of the device (frequencies, Q, quadrature,
demodulation phase, scale factor, in-phase coupling, amplitude set-point); its value is the
deviation from the data-sheet device (0 = nominal) and its prior is the tolerance. An *effect*
knob is a parameter of a library effect (:data:`fmvmg_sim.effects.MODELS`) folded into the device
through :class:`fmvmg_sim.effects.EffectSet`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from ..device import Device
from ..diagram import design_phase_trim
from ..effects import MODELS, EffectSet


@dataclass(frozen=True)
class Knob:
    """One nominal-parameter deviation.

    Parameters
    ----------
    name : str
        Knob name (unit in the name).
    path : tuple of str
        Key path into ``Device.values`` (for ``trim``: the demodulator).
    kind : str
        ``"rel"``: value * (1 + x); ``"abs"``: value + x; ``"trim_mrad"``: phase trim = designed + x mrad;
        ``"freq_rel"``: both mode frequencies * (1 + x).
    tolerance : float
        Unit-to-unit tolerance (half-width of the uniform spread the case generator draws from; the
        calibration uses it as the prior standard deviation).
    step : float
        Finite-difference step for sensitivities.
    """

    name: str
    path: tuple
    kind: str
    tolerance: float
    step: float


#: The nominal parameters the calibration moves (device tolerances, [E] engineering estimates).
NOMINAL_KNOBS: tuple[Knob, ...] = (
    Knob("f_modes_rel", ("mechanics",), "freq_rel", 5e-3, 1e-5),
    Knob("split_Hz", ("mechanics", "f_sense_Hz"), "abs", 10.0, 0.5),
    Knob("q_drive_rel", ("mechanics", "q_drive"), "rel", 0.2, 0.01),
    Knob("q_sense_rel", ("mechanics", "q_sense"), "rel", 0.2, 0.01),
    Knob("quadrature_rel", ("mechanics", "quadrature_rate_dps"), "rel", 0.2, 0.01),
    Knob("demod_phase_mrad", ("circuit", "demodulator", "phase_trim"), "trim_mrad", 3.0, 0.1),
    Knob("sense_gain_rel", ("circuit", "sense_amp2", "gain"), "rel", 0.02, 1e-3),
    Knob("omega_c_dps", ("mechanics", "damping_coupling_rate_dps"), "abs", 0.3, 0.01),
    Knob("vref_rel", ("circuit", "reference", "vref_V"), "rel", 0.01, 1e-4),
)
NOMINAL_NAMES = tuple(k.name for k in NOMINAL_KNOBS)
#: Calibration bounds in tolerances: a unit is within its tolerance (with this margin for the
#: linearisation); a fit that needs more is itself evidence of an unmodelled effect, so the nominal
#: parameters are not allowed to absorb an effect's signature by leaving their tolerance.
BOUND_TOLERANCES = 1.5
KNOBS_BY_NAME = {k.name: k for k in NOMINAL_KNOBS}


def apply_nominal(device: Device, values: dict) -> Device:
    """The device with nominal-knob deviations applied.

    Parameters
    ----------
    device : Device
        The data-sheet device (deviations are relative to it).
    values : dict
        ``{knob name: deviation}``; missing knobs stay nominal.

    Returns
    -------
    Device
    """
    v = copy.deepcopy(device.values)
    # the reference phase is trimmed once on the data-sheet design; a unit's phase error is a deviation from it
    trim = design_phase_trim(device)
    v["circuit"]["demodulator"]["phase_trim"] = trim
    for name, x in values.items():
        if x == 0.0:
            continue
        k = KNOBS_BY_NAME[name]
        if k.kind == "freq_rel":
            v["mechanics"]["f_drive_Hz"] *= 1.0 + x
            v["mechanics"]["f_sense_Hz"] *= 1.0 + x
        elif k.kind == "trim_mrad":
            v["circuit"]["demodulator"]["phase_trim"] = trim + 1e-3 * x
        else:
            d = v
            for key in k.path[:-1]:
                d = d[key]
            d[k.path[-1]] = d[k.path[-1]] * (1.0 + x) if k.kind == "rel" else d[k.path[-1]] + x
    return Device(v, device.path)


def apply_effects(device: Device, effects: dict) -> Device:
    """The device with the temperature-law effects of ``effects`` folded in.

    Parameters
    ----------
    device : Device
    effects : dict
        ``{effect: {param: value}}`` (complete parameter sets).

    Returns
    -------
    Device
    """
    return EffectSet(effects).apply_to_device(device) if effects else device


def effect_params(name: str) -> dict:
    """Parameter specs of effect ``name`` (:class:`fmvmg_sim.effects.Param`).

    Parameters
    ----------
    name : str

    Returns
    -------
    dict
    """
    return MODELS[name]
