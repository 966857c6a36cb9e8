"""What a nominal model does not know exactly: the knobs a calibration may move, each with its tolerance.

A real unit never matches its nominal model. Three kinds of difference are stated as data, each
knob with a tolerance in the device file's ``[tolerance]`` table (a scenario overrides them under
``[device.tolerance]``):

* **unit** knobs: the unit-to-unit spread of the nominal values at the reference temperature (mode
  frequencies and split, Q, quadrature, demodulation phase, scale factor, in-phase coupling, Vref);
* **law** knobs: the temperature coefficients the device file marks as engineering estimates (the
  frequency law, the Q law, the amplifiers' bandwidth and with it their phase, Vref, quadrature and
  mode split). A law calibrated beyond its tolerance is what the matching library effect describes
  (:attr:`Knob.effect`);
* **channel** knobs: the offset and the gain of the data acquisition on each auxiliary channel, the
  offset of the rate output (its gain is the sense gain, a unit knob), and the timing of the temperature
  reading against the channels' sample intervals (a point reading at the time stamp, or a mean over the
  interval as the channels are, differ by half a sample: on a 2 K/min ramp at 1 Hz, 17 mK).

A knob's value is its deviation from the device file (0 = nominal); its tolerance is the half-width of
the spread a calibration expects (the prior standard deviation of the calibration; the benchmark draws
units uniformly within it). A tolerance of 0 holds the knob at its nominal value. Calibrations may go
:data:`BOUND_TOLERANCES` tolerances out, no further: beyond that the record shows a unit the nominal
model with its stated uncertainty does not describe, which is the diagnosis' business.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .schema import Num

#: Calibration bounds, in tolerances.
BOUND_TOLERANCES = 1.5


@dataclass(frozen=True)
class Knob:
    """One thing the nominal model does not know exactly.

    Parameters
    ----------
    name : str
        Knob name, unit in the name (its tolerance is in the same unit).
    group : str
        ``"unit"``, ``"law"`` or ``"channel"``.
    kind : str
        How it acts. On the device (:func:`fmvmg_sim.diagnosis.parameters.apply_nominal`): ``"rel"``
        (value x (1 + x)), ``"abs"`` (value + x), ``"abs_all"`` (+ x on every path in ``paths``),
        ``"freq_rel"`` (both mode frequencies x (1 + x)), ``"trim_mrad"`` (demodulation phase trim + x
        mrad), ``"inv_rel"`` (value / (1 + x): a Q through its damping, which the AGC effort and the sense phase
        follow linearly). On a recorded channel: ``"offset"`` (+ x), ``"gain"`` (x (1 + x)), ``"gain_tc"``
        (x (1 + x (T - T0)), T the recorded temperature, T0 the device's reference) and ``"delay"`` (the
        temperature reading at time t is the temperature at t - x).
    paths : tuple of tuple of str
        Key paths into the device values (device knobs), or ``(("<channel>",),)`` (channel knobs).
    step : float
        Finite-difference step of its sensitivity.
    meaning : str
        One line for the documentation and the report.
    effect : str, optional
        The library effect that describes this law beyond its tolerance (law knobs).
    """

    name: str
    group: str
    kind: str
    paths: tuple
    step: float
    meaning: str
    effect: str | None = None

    @property
    def channel(self) -> str | None:
        """The recorded channel a channel knob acts on (None for device knobs)."""
        return self.paths[0][0] if self.group == "channel" else None

    @property
    def on_device(self) -> bool:
        """Whether the knob changes the device (else it acts on a recorded channel)."""
        return self.group != "channel"


def _k(name, group, kind, paths, step, meaning, effect=None) -> Knob:
    return Knob(name, group, kind, tuple(tuple(p) for p in paths), step, meaning, effect)


_AMPS = ("drive_amp", "sense_amp1", "sense_amp2")

#: Every knob, in the order calibrations and reports list them.
KNOBS: tuple[Knob, ...] = (
    _k("f_modes_rel", "unit", "freq_rel", [("mechanics",)], 1e-5, "both mode frequencies, relative"),
    _k("split_Hz", "unit", "abs", [("mechanics", "f_sense_Hz")], 0.5, "mode split (sense-mode frequency)"),
    _k("q_drive_rel", "unit", "inv_rel", [("mechanics", "q_drive")], 0.01,
       "drive-mode damping 1/Q, relative (Q / (1 + x))"),
    _k("q_sense_rel", "unit", "inv_rel", [("mechanics", "q_sense")], 0.01,
       "sense-mode damping 1/Q, relative (Q / (1 + x))"),
    _k("quadrature_rel", "unit", "rel", [("mechanics", "quadrature_rate_dps")], 0.01,
       "quadrature coupling, relative (its sign is read from the record)"),
    _k("demod_phase_mrad", "unit", "trim_mrad", [("circuit", "demodulator", "phase_trim")], 0.1,
       "demodulation phase error at the reference temperature"),
    _k("sense_gain_rel", "unit", "rel", [("circuit", "sense_amp2", "gain")], 1e-3,
       "sense-chain gain (the scale factor), relative"),
    _k("omega_c_dps", "unit", "abs", [("mechanics", "damping_coupling_rate_dps")], 0.01,
       "damping coupling, as an in-phase rate"),
    _k("vref_rel", "unit", "rel", [("circuit", "reference", "vref_V")], 1e-4, "amplitude set-point Vref, relative"),
    _k("tcf_linear_per_K", "law", "abs", [("thermal", "tcf_linear_per_K")], 1e-8,
       "frequency temperature coefficient, linear"),
    _k("tcf_quadratic_per_K2", "law", "abs", [("thermal", "tcf_quadratic_per_K2")], 1e-9,
       "frequency temperature coefficient, quadratic"),
    _k("q_gas_exponent", "law", "abs", [("thermal", "q_gas_exponent")], 0.05,
       "Q law: exponent n of the gas damping Q_gas ~ T^-n", "q_factor_drift"),
    _k("q_curvature_per_K2", "law", "abs", [("thermal", "q_curvature_per_K2")], 1e-7,
       "Q law: its curvature, ln Q + c (T - T0)^2 (the mix of gas, thermoelastic and anchor losses)"),
    _k("q_solid_damping_rel", "law", "inv_rel", [("thermal", "q_ted"), ("thermal", "q_anchor")], 0.02,
       "Q law: the thermoelastic and anchor damping, relative (Q_TED and Q_anchor / (1 + x)): their share of the "
       "damping beside the gas's, which sets the Q law's shape"),
    _k("gbw_tc_per_K", "law", "abs_all", [("circuit", a, "gbw_tc_per_K") for a in _AMPS], 1e-4,
       "amplifier gain-bandwidth temperature coefficient (every amplifier): their phase drift", "demod_phase_drift"),
    _k("amp_gain_tc_per_K", "law", "abs_all", [("circuit", a, "gain_tc_per_K") for a in _AMPS], 1e-6,
       "amplifier gain temperature coefficient (every amplifier): the drive amplitude and the scale factor"),
    _k("vref_tc_per_K", "law", "abs", [("circuit", "reference", "vref_tc_per_K")], 1e-6,
       "Vref temperature coefficient", "reference_drift"),
    _k("quadrature_tc_per_K", "law", "abs", [("thermal", "quadrature_tc_per_K")], 1e-4,
       "quadrature temperature coefficient", "quadrature_drift"),
    _k("split_tcf_per_K", "law", "abs", [("thermal", "split_tcf_per_K")], 5e-8,
       "difference of the two modes' TCF (mode-split law)", "mode_split_drift"),
    _k("rate_offset_V", "channel", "offset", [("rate_V",)], 1e-4, "rate output offset"),
    _k("quadrature_offset_V", "channel", "offset", [("quadrature_V",)], 1e-4, "quadrature channel offset"),
    _k("quadrature_gain_rel", "channel", "gain", [("quadrature_V",)], 1e-4, "quadrature channel gain, relative"),
    _k("drive_amplitude_offset_V", "channel", "offset", [("drive_amplitude_V",)], 1e-5,
       "drive-amplitude channel offset"),
    _k("drive_amplitude_gain_rel", "channel", "gain", [("drive_amplitude_V",)], 1e-4,
       "drive-amplitude channel gain, relative"),
    _k("agc_effort_offset_V", "channel", "offset", [("agc_effort_V",)], 1e-4, "AGC-effort channel offset"),
    _k("agc_effort_gain_rel", "channel", "gain", [("agc_effort_V",)], 1e-4, "AGC-effort channel gain, relative"),
    _k("agc_effort_tc_per_K", "channel", "gain_tc", [("agc_effort_V",)], 1e-6,
       "AGC-effort gain temperature coefficient between the drive force and the record (the PI stage, its "
       "acquisition, the drive's references VDC and Vdac)"),
    _k("drive_frequency_offset_Hz", "channel", "offset", [("drive_frequency_Hz",)], 1e-3,
       "drive-frequency channel offset"),
    _k("drive_frequency_gain_rel", "channel", "gain", [("drive_frequency_Hz",)], 1e-7,
       "drive-frequency channel gain (the counter's clock), relative"),
    _k("temperature_delay_s", "channel", "delay", [("temperature_C",)], 0.05,
       "how much later than the channels' sample intervals the temperature reading is taken"),
)
KNOBS_BY_NAME = {k.name: k for k in KNOBS}
#: Knobs by the library effect that describes their law beyond its tolerance.
LAW_OF_EFFECT = {k.effect: k for k in KNOBS if k.effect}

#: How far the model's laws may be off beyond the temperatures a calibration saw: a channel calibrated on a window
#: and extrapolated ``d`` kelvin beyond its temperatures is uncertain by this times ``d^2`` of its value (a law whose
#: value and slope the window fixes is still off in its curvature; a precise channel, the AGC effort read to a few
#: parts per million, shows that as a gap the null does not have).
LAW_CURVATURE = "law_curvature_per_K2"

#: The device file's ``[tolerance]`` table.
TOLERANCE_SCHEMA = {**{k.name: Num(lo=0.0) for k in KNOBS}, LAW_CURVATURE: Num(lo=0.0)}


def tolerances(device) -> dict:
    """Each knob's tolerance for a device (its ``[tolerance]`` table, with any scenario override applied).

    Parameters
    ----------
    device : fmvmg_sim.device.Device

    Returns
    -------
    dict
        ``{knob name: tolerance}`` in :data:`KNOBS` order.
    """
    tab = device.values.get("tolerance", {})
    return {k.name: float(tab.get(k.name, 0.0)) for k in KNOBS}


def law_curvature(device) -> float:
    """The relative accuracy of the laws' curvature (1/K^2) of a device (:data:`LAW_CURVATURE`).

    Parameters
    ----------
    device : fmvmg_sim.device.Device

    Returns
    -------
    float
    """
    return float(device.values.get("tolerance", {}).get(LAW_CURVATURE, 0.0))


def apply_channels(values: dict, channels: dict, reference_temperature_C: float = 25.0) -> dict:
    """Recorded channels through the channel knobs: ``(1 + gain)(1 + tc (T - T0)) x + offset``, the temperature read
    late.

    Parameters
    ----------
    values : dict
        ``{knob name: deviation}`` (device knobs are ignored).
    channels : dict
        ``{channel: ndarray}`` of a record (``time_s`` needed for a temperature delay, ``temperature_C`` for a gain
        temperature coefficient); channels no knob names pass unchanged.
    reference_temperature_C : float, optional
        ``T0`` of the gain temperature coefficients (the device's reference temperature).

    Returns
    -------
    dict
        New arrays for the channels a knob changed.
    """
    by_kind = {"gain": {}, "offset": {}, "gain_tc": {}}
    delay = 0.0
    for name, x in values.items():
        k = KNOBS_BY_NAME[name]
        if k.group != "channel" or x == 0.0:
            continue
        if k.kind == "delay":
            delay = float(x)
        else:
            by_kind[k.kind][k.channel] = float(x)
    out = dict(channels)
    dT = np.asarray(out.get("temperature_C", np.nan), dtype=float) - reference_temperature_C
    for c in set().union(*by_kind.values()):
        if c in out:
            tc = by_kind["gain_tc"].get(c, 0.0) * dT if c in by_kind["gain_tc"] else 0.0
            out[c] = out[c] * (1.0 + by_kind["gain"].get(c, 0.0)) * (1.0 + tc) + by_kind["offset"].get(c, 0.0)
    if delay and "temperature_C" in out:
        t = np.asarray(out["time_s"], dtype=float)
        out["temperature_C"] = np.interp(t - delay, t, np.asarray(out["temperature_C"], dtype=float))
    return out
