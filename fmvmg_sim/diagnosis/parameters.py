"""Knobs on a device: the nominal model's stated uncertainty and the library effects, for calibration and attribution.

A *nominal* knob (:mod:`fmvmg_sim.uncertainty`) is something the nominal model does not know exactly: a unit
value, a temperature law or a channel's offset and gain; its value is the deviation from the device file
(0 = nominal) and its prior standard deviation is its tolerance. An *effect* knob is a parameter of a library
effect (:data:`fmvmg_sim.effects.MODELS`) folded into the device through :class:`fmvmg_sim.effects.EffectSet`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from ..device import Device
from ..diagram import design_phase_trim
from ..effects import MODELS, EffectSet
from ..uncertainty import BOUND_TOLERANCES, KNOBS, KNOBS_BY_NAME, tolerances


@dataclass(frozen=True)
class KnobSet:
    """The knobs a calibration moves for one device: those of :data:`fmvmg_sim.uncertainty.KNOBS` with a
    non-zero tolerance, in that order.

    Parameters
    ----------
    knobs : tuple of Knob
    tolerance : ndarray
        Each knob's tolerance (its prior standard deviation).
    """

    knobs: tuple
    tolerance: np.ndarray

    @classmethod
    def of(cls, device: Device) -> "KnobSet":
        """The knobs of ``device`` (its ``[tolerance]`` table).

        Parameters
        ----------
        device : Device

        Returns
        -------
        KnobSet
        """
        tol = tolerances(device)
        kept = tuple(k for k in KNOBS if tol[k.name] > 0.0)
        return cls(kept, np.array([tol[k.name] for k in kept], dtype=float))

    def __len__(self) -> int:
        return len(self.knobs)

    @property
    def names(self) -> list:
        """Knob names, in order."""
        return [k.name for k in self.knobs]

    def tolerance_of(self, name: str) -> float:
        """The tolerance of knob ``name``.

        Parameters
        ----------
        name : str

        Returns
        -------
        float
        """
        return float(self.tolerance[self.names.index(name)])

    @property
    def device_knobs(self) -> tuple:
        """The knobs that change the device (their sensitivities are response tables)."""
        return tuple(k for k in self.knobs if k.on_device)

    @property
    def lo(self) -> np.ndarray:
        """Lower calibration bounds (a relative knob never takes its value below a tenth)."""
        return np.array([max(-BOUND_TOLERANCES * t, -0.9) if k.kind in ("rel", "inv_rel", "gain", "freq_rel")
                         else -BOUND_TOLERANCES * t for k, t in zip(self.knobs, self.tolerance)])

    @property
    def hi(self) -> np.ndarray:
        """Upper calibration bounds."""
        return BOUND_TOLERANCES * self.tolerance


def apply_nominal(device: Device, values: dict) -> Device:
    """The device with nominal-knob deviations applied.

    Parameters
    ----------
    device : Device
        The data-sheet device (deviations are relative to it).
    values : dict
        ``{knob name: deviation}``; missing knobs stay nominal, channel knobs are ignored (they act on the
        recorded channels: :func:`fmvmg_sim.uncertainty.apply_channels`).

    Returns
    -------
    Device
    """
    v = copy.deepcopy(device.values)
    # the reference phase is trimmed once on the data-sheet design; a unit's phase error is a deviation from it
    trim = design_phase_trim(device)
    v["circuit"]["demodulator"]["phase_trim"] = trim
    for name, x in values.items():
        k = KNOBS_BY_NAME[name]
        if x == 0.0 or not k.on_device:
            continue
        if k.kind == "freq_rel":
            v["mechanics"]["f_drive_Hz"] *= 1.0 + x
            v["mechanics"]["f_sense_Hz"] *= 1.0 + x
        elif k.kind == "trim_mrad":
            v["circuit"]["demodulator"]["phase_trim"] = trim + 1e-3 * x
        else:
            for path in k.paths:
                d = v
                for key in path[:-1]:
                    d = d[key]
                v0 = d.get(path[-1], 0.0)  # an optional law (a curvature) is 0 when the device file leaves it out
                d[path[-1]] = deviated(k.kind, v0, x)
    return Device(v, device.path)


def deviated(kind: str, v0, x):
    """A value ``v0`` at a knob's deviation ``x``: ``v0 (1 + x)`` for a relative knob, ``v0 / (1 + x)`` for one on
    the inverse (a Q through its damping), ``v0 + x`` otherwise.

    Parameters
    ----------
    kind : str
        The knob's kind (:class:`fmvmg_sim.uncertainty.Knob`).
    v0 : float or ndarray
    x : float or ndarray

    Returns
    -------
    float or ndarray
    """
    return v0 * (1.0 + x) if kind == "rel" else v0 / (1.0 + x) if kind == "inv_rel" else v0 + x


def knob_values(device: Device, name: str, x: float) -> tuple[float, float]:
    """A knob's nominal value and its value at deviation ``x``, in the quantity it acts on (a Q, a coefficient in
    1/K, a channel gain; the demodulation phase error in mrad, the first mode frequency for ``f_modes_rel``).

    Parameters
    ----------
    device : Device
    name : str
    x : float
        The knob's deviation.

    Returns
    -------
    nominal, calibrated : float
    """
    k = KNOBS_BY_NAME[name]
    if k.kind == "gain":
        return 1.0, 1.0 + x
    if k.kind in ("offset", "delay", "trim_mrad"):
        return 0.0, x
    if k.kind == "freq_rel":
        f = float(device.values["mechanics"]["f_drive_Hz"])
        return f, f * (1.0 + x)
    d = device.values
    for key in k.paths[0][:-1]:
        d = d[key]
    v = float(d.get(k.paths[0][-1], 0.0))
    return v, deviated(k.kind, v, x)


def flip_quadrature(device: Device) -> Device:
    """The device with its quadrature coupling of the other sign (a unit's imbalance has either sign).

    Parameters
    ----------
    device : Device

    Returns
    -------
    Device
    """
    v = copy.deepcopy(device.values)
    v["mechanics"]["quadrature_rate_dps"] = -v["mechanics"]["quadrature_rate_dps"]
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
