"""Devices as data: load a device file from ``scenarios/devices/`` and evaluate it at a temperature.

A device file holds the MEMS element (``[mechanics]``, ``[thermal]``), its default
electronics (``[circuit.*]``) and noise (``[noise]``); every number is
``{ value = ..., source = "[S|D|E] ..." }``. :meth:`Device.at` applies the temperature
laws and returns an :class:`OperatingPoint`, the parameter values of every block at
that temperature, from which :mod:`fmvmg_sim.diagram` builds the blocks.
"""

from __future__ import annotations

import copy
import json
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import thermal_laws as law
from .errors import InputError
from .paths import scenarios_dir
from .schema import Bool, Choice, Num, Text, validate_tree
from .tomlio import load_toml
from .pll_config import DRIVE_TOPOLOGIES, PLL_SCHEMA, check_pll_values, pll_at
from .uncertainty import TOLERANCE_SCHEMA

_AMP = {"gain": Num(), "gbw_Hz": Num(positive=True), "gbw_tc_per_K": Num(-0.05, 0.05),
        "offset_V": Num(-10, 10), "gain_tc_per_K": Num(-0.01, 0.01)}

DEVICE_SCHEMA = {
    "name": Text(), "description": Text(),
    "reference_temperature_C": Num(-273.15, 500),
    "mechanics": {
        "f_drive_Hz": Num(positive=True), "f_sense_Hz": Num(positive=True),
        "m_drive_kg": Num(positive=True), "m_sense_kg": Num(positive=True),
        "m_coriolis_kg": Num(positive=True),
        "q_drive": Num(1.0, 1e9), "q_sense": Num(1.0, 1e9),
        "quadrature_rate_dps": Num(-1e5, 1e5), "damping_coupling_rate_dps": Num(-1e4, 1e4),
        "k_electrostatic_sense_N_per_m": Num(), "duffing_k3_drive_N_per_m3": Num(),
        "duffing_k3_rel": Num(-0.1, 0.1),
    },
    "thermal": {
        "tcf_linear_per_K": Num(-1e-3, 1e-3), "tcf_quadratic_per_K2": Num(-1e-5, 1e-5),
        "split_tcf_per_K": Num(-1e-4, 1e-4), "q_ted": Num(positive=True),
        "q_anchor": Num(positive=True), "q_gas_exponent": Num(-10, 10),
        "quadrature_tc_per_K": Num(-0.1, 0.1),
        "q_extra_tc_per_K": Num(-0.1, 0.1), "split_extra_Hz_per_K": Num(-10, 10),
        "q_curvature_per_K2": Num(-1e-3, 1e-3),
    },
    "circuit": {
        "drive_pickoff": {"bias_V": Num(positive=True), "dC_dx_F_per_m": Num(positive=True),
                          "c_feedback_F": Num(positive=True)},
        "drive_amp": _AMP,
        "phase_shifter": {"design_frequency_Hz": Num(positive=True), "trim_rad": Num(-1.5, 1.5),
                          "rc_tc_per_K": Num(-0.01, 0.01)},
        "rectifier": {"gain": Num(positive=True), "offset_tc_V_per_K": Num(-0.1, 0.1)},
        "amplitude_lpf": {"f_c_Hz": Num(positive=True)},
        "reference": {"vref_V": Num(positive=True), "vref_tc_per_K": Num(-0.01, 0.01)},
        "pi": {"kp": Num(lo=0), "ki_per_s": Num(lo=0), "u_min_V": Num(), "u_max_V": Num()},
        "modulator": {"carrier": Choice(("normalized", "pickoff")), "vdac_V": Num(positive=True),
                      "k_per_V": Num(positive=True)},
        "comb_drive": {"vdc_V": Num(positive=True), "dC_dx_F_per_m": Num(positive=True),
                       "topology": Choice(("push-pull", "single-sided")), "asymmetry": Num(-1, 1)},
        "sense_pickoff": {"bias_V": Num(positive=True), "dC_dx_F_per_m": Num(positive=True),
                          "c_feedback_F": Num(positive=True), "c_feedthrough_F": Num(lo=0),
                          "sign": Num(-1, 1), "c_feedthrough_tc_per_K": Num(-0.1, 0.1)},
        "sense_amp1": _AMP, "sense_amp2": _AMP,
        "demodulator": {"k_per_V": Num(positive=True), "phase_trim": Num(-3.2, 3.2, allow=("auto",)),
                        "phase_tc_rad_per_K": Num(-0.1, 0.1)},
        "output_lpf": {"f_c_Hz": Num(positive=True), "gain": Num()},
        # closed-loop sense (fmvmg_sim.rebalance): optional tables, open loop without them
        "sense": {"topology": Choice(("open-loop", "force-rebalance"))},
        "rebalance": {"dC_dx_F_per_m": Num(positive=True), "vdc_V": Num(positive=True),
                      "k_mod_per_V": Num(positive=True), "filter_f_c_Hz": Num(positive=True),
                      "kp": Num(lo=0), "ki_per_s": Num(positive=True), "kd_s": Num(lo=0)},
        "quadrature_control": {"enabled": Bool(), "dk_dV_N_per_m_per_V": Num(positive=True),
                               "filter_f_c_Hz": Num(positive=True), "kp": Num(lo=0), "ki_per_s": Num(positive=True)},
        # the drive loop's topology and, for a PLL drive, its electronics (fmvmg_sim.pll_drive)
        "drive": {"topology": Choice(DRIVE_TOPOLOGIES)},
        "pll": PLL_SCHEMA,
    },
    "noise": {
        "sense_input_V_per_sqrtHz": Num(lo=0), "drive_input_V_per_sqrtHz": Num(lo=0),
        "flicker_phase_rad2": Num(lo=0), "flicker_output_dps2": Num(lo=0),
        "rate_random_walk_dps_per_sqrt_s": Num(lo=0), "quantization_lsb_V": Num(lo=0),
    },
    # what the nominal values and laws are not known to better than (fmvmg_sim.uncertainty)
    "tolerance": TOLERANCE_SCHEMA,
}

#: Keys a device file may leave out (they default to zero: the unmodelled effects switch them on).
OPTIONAL_KEYS = {"mechanics.duffing_k3_rel", "thermal.q_extra_tc_per_K", "thermal.split_extra_Hz_per_K",
                 "thermal.q_curvature_per_K2",
                 "circuit.sense_pickoff.c_feedthrough_tc_per_K", "circuit.demodulator.phase_tc_rad_per_K",
                 "circuit.sense", "circuit.rebalance", "circuit.quadrature_control", "circuit.drive", "circuit.pll"}

DEVICES_DIR = scenarios_dir() / "devices"

#: Temperature coefficients that follow the board (the electronics); every other law follows the die.
BOARD_LAWS = ("circuit.drive_amp.gain_tc_per_K", "circuit.drive_amp.gbw_tc_per_K",
              "circuit.sense_amp1.gain_tc_per_K", "circuit.sense_amp1.gbw_tc_per_K",
              "circuit.sense_amp2.gain_tc_per_K", "circuit.sense_amp2.gbw_tc_per_K",
              "circuit.phase_shifter.rc_tc_per_K", "circuit.rectifier.offset_tc_V_per_K",
              "circuit.reference.vref_tc_per_K", "circuit.demodulator.phase_tc_rad_per_K",
              "circuit.sense_pickoff.c_feedthrough_tc_per_K")

#: Devices whose derived numbers (reference diagram, nominal scale factor) are kept, by content (a few kB each).
DERIVED_CACHE_SIZE = 512
_DERIVED: OrderedDict = OrderedDict()


def _derived(device: "Device", name: str, compute):
    """``compute()`` once per device content and name (least recently used dropped first)."""
    key = (device.content_key, name)
    if key in _DERIVED:
        _DERIVED.move_to_end(key)
        return _DERIVED[key]
    value = _DERIVED[key] = compute()
    while len(_DERIVED) > DERIVED_CACHE_SIZE:
        _DERIVED.popitem(last=False)
    return value


@dataclass
class OperatingPoint:
    """Every block parameter of the device and circuit at one operating temperature.

    Parameters
    ----------
    temperature_C : float
        Die temperature (the MEMS laws).
    values : dict
        ``{"mechanics": {...}, "circuit": {...}, "noise": {...}}`` with the temperature
        laws applied; see :meth:`Device.at`.
    board_temperature_C : float, optional
        Board temperature (the electronics laws); ``None`` when it equals the die temperature.
    """

    temperature_C: float
    values: dict = field(default_factory=dict)
    board_temperature_C: float | None = None

    def __getitem__(self, key):
        return self.values[key]


@dataclass
class Device:
    """A validated device description.

    Parameters
    ----------
    values : dict
        Validated values by key path (``values["mechanics"]["q_drive"]``).
    path : str
        The file it came from.
    """

    values: dict
    path: str = ""

    @property
    def name(self) -> str:
        """Device name (e.g. ``fmvmg-a``)."""
        return self.values.get("name", Path(self.path).stem)

    @property
    def reference_temperature_C(self) -> float:
        """Temperature at which the nominal values hold."""
        return float(self.values["reference_temperature_C"])

    @property
    def drive_topology(self) -> str:
        """The drive loop: ``"self-oscillating"`` (the phase-shifter loop, the default) or ``"pll"``."""
        return self.values["circuit"].get("drive", {}).get("topology", "self-oscillating")

    @property
    def content_key(self) -> str:
        """The values as canonical JSON: devices with equal values share it (derived numbers are cached under it)."""
        return json.dumps(self.values, sort_keys=True, default=repr)

    @property
    def reference_diagram(self):
        """The diagram (:class:`fmvmg_sim.diagram.Diagram`) at the reference temperature, die and board.

        Built once per device content and shared by every caller: read it, do not change it.
        """
        # the diagram module imports this one, and its blocks python-control (2 s), which loading a device
        # does not need: imported on first use
        from .diagram import build_diagram
        return _derived(self, "reference_diagram", lambda: build_diagram(self, self.reference_temperature_C))

    @property
    def nominal_scale_factor_V_per_dps(self) -> float:
        """Rate output per deg/s of the averaged steady state at the reference temperature (V/(deg/s)).

        A record's ``rate_dps`` is its ``rate_V`` divided by the nominal device's (the scenario's
        device without effects). Computed once per device content.
        """
        from .averaged import scale_factor_V_per_dps  # imports this module through the diagram (above)
        if self.drive_topology == "pll":
            from .pll_drive import build_pll_drive, pll_scale_factor_V_per_dps
            return _derived(self, "nominal_scale_factor_V_per_dps", lambda: pll_scale_factor_V_per_dps(
                build_pll_drive(self, self.reference_temperature_C, dg=self.reference_diagram)))
        return _derived(self, "nominal_scale_factor_V_per_dps",
                        lambda: scale_factor_V_per_dps(self.reference_diagram))

    def with_overrides(self, overrides: dict, where: str) -> "Device":
        """A copy with some values replaced (validated against the same schema).

        Parameters
        ----------
        overrides : dict
            Nested dict of plain values (a scenario's ``[device]`` table).
        where : str
            File name for messages.

        Returns
        -------
        Device
        """
        checked = validate_tree(overrides, DEVICE_SCHEMA, where, prefix="device.")
        merged = copy.deepcopy(self.values)
        _merge(merged, checked)
        check_pll_values(merged, where)
        return Device(merged, self.path)

    def at(self, temperature_C: float, board_C: float | None = None) -> OperatingPoint:
        """Apply the temperature laws: the block parameters at a die and a board temperature.

        The MEMS laws (mode frequencies and split, Q, quadrature, damping coupling,
        electrostatic and Duffing stiffness, Brownian-noise temperature) follow the die;
        the electronics laws (amplifier gains and bandwidths, phase-shifter RC, rectifier
        offset, Vref, demodulation-phase drift, the board's feedthrough capacitance) follow
        the board. :data:`BOARD_LAWS` lists the latter; docs/model.md says why.

        Parameters
        ----------
        temperature_C : float
            Die temperature in degC.
        board_C : float, optional
            Board (electronics) temperature in degC; default: the die temperature.

        Returns
        -------
        OperatingPoint
        """
        v = self.values
        me, th, ci = v["mechanics"], v["thermal"], v["circuit"]
        T0 = self.reference_temperature_C
        dT = float(temperature_C) - T0
        dTb = dT if board_C is None else float(board_C) - T0
        f_d = law.frequency_Hz(me["f_drive_Hz"], dT, th["tcf_linear_per_K"], th["tcf_quadratic_per_K2"])
        f_s_mech = (law.frequency_Hz(me["f_sense_Hz"], dT, th["tcf_linear_per_K"], th["tcf_quadratic_per_K2"])
                    + me["f_drive_Hz"] * th["split_tcf_per_K"] * dT + th.get("split_extra_Hz_per_K", 0.0) * dT)
        k_s = me["m_sense_kg"] * (2 * np.pi * f_s_mech) ** 2 + me["k_electrostatic_sense_N_per_m"]
        if k_s <= 0:
            raise ValueError("electrostatic softening exceeds the sense stiffness")
        f_s = np.sqrt(k_s / me["m_sense_kg"]) / (2 * np.pi)
        q = {m: float(law.quality_factor_law(me[f"q_{m}"], temperature_C, T0, th["q_ted"], th["q_anchor"],
                                             th["q_gas_exponent"], th.get("q_extra_tc_per_K", 0.0),
                                             th.get("q_curvature_per_K2", 0.0)))
             for m in ("drive", "sense")}
        omega_q = np.deg2rad(me["quadrature_rate_dps"]) * (1 + th["quadrature_tc_per_K"] * dT)
        k_q = 2 * me["m_coriolis_kg"] * 2 * np.pi * f_d * omega_q
        c_q = 2 * me["m_coriolis_kg"] * np.deg2rad(me["damping_coupling_rate_dps"]) * (me["q_sense"] / q["sense"])
        mech = dict(m_drive_kg=me["m_drive_kg"], m_sense_kg=me["m_sense_kg"], m_coriolis_kg=me["m_coriolis_kg"],
                    f_drive_Hz=float(f_d), f_sense_Hz=float(f_s), q_drive=q["drive"], q_sense=q["sense"],
                    k_quad_N_per_m=float(k_q), c_quad_N_s_per_m=float(c_q),
                    k3_drive_N_per_m3=me["duffing_k3_drive_N_per_m3"] + self._k3_from_rel(),
                    temperature_K=temperature_C + law.KELVIN)

        # --- the electronics, on the board ---
        def amp(d):
            return dict(gain=law.linear_tc(d["gain"], dTb, d["gain_tc_per_K"]),
                        gbw_Hz=law.linear_tc(d["gbw_Hz"], dTb, d["gbw_tc_per_K"]), offset_V=d["offset_V"])

        ps = ci["phase_shifter"]
        circ = {
            "drive_pickoff": dict(ci["drive_pickoff"]),
            "drive_amp": amp(ci["drive_amp"]),
            "phase_shifter": dict(design_frequency_Hz=ps["design_frequency_Hz"], trim_rad=ps["trim_rad"],
                                  rc_tc_per_K=ps["rc_tc_per_K"], delta_T_K=dTb),
            "rectifier": dict(gain=ci["rectifier"]["gain"], offset_V=ci["rectifier"]["offset_tc_V_per_K"] * dTb),
            "amplitude_lpf": dict(ci["amplitude_lpf"]),
            "reference": dict(vref_V=law.linear_tc(ci["reference"]["vref_V"], dTb,
                                                   ci["reference"]["vref_tc_per_K"])),
            "pi": dict(ci["pi"]),
            "modulator": dict(ci["modulator"]),
            "comb_drive": dict(ci["comb_drive"]),
            "sense_pickoff": _feedthrough_at(ci["sense_pickoff"], dTb),
            "sense_amp1": amp(ci["sense_amp1"]),
            "sense_amp2": amp(ci["sense_amp2"]),
            "demodulator": {k: val for k, val in ci["demodulator"].items() if k != "phase_tc_rad_per_K"},
            "output_lpf": dict(ci["output_lpf"]),
        }
        circ.update({k: dict(ci[k]) for k in ("sense", "rebalance", "quadrature_control") if k in ci})
        if self.drive_topology == "pll":  # the PLL's oscillator and loop filter, on the board
            circ["pll"] = pll_at(ci.get("pll", {}), me["f_drive_Hz"], dTb)
        return OperatingPoint(float(temperature_C), {
            "mechanics": mech, "circuit": circ, "noise": dict(v["noise"]), "delta_T_K": dT,
            "board_delta_T_K": dTb,
            "demod_phase_drift_rad": ci["demodulator"].get("phase_tc_rad_per_K", 0.0) * dTb},
            None if board_C is None else float(board_C))

    def nominal_amplitude_m(self) -> float:
        """Drive amplitude the AGC holds at the reference temperature, ``Vref / (G_rect K_dx)``.

        ``G_rect = 2 G_r / pi`` is the rectifier's describing gain and ``K_dx`` the drive pickoff's gain
        times the drive amplifier's (the phase shifter passes the amplitude unchanged).

        Returns
        -------
        float
        """
        # blocks import python-control (2 s), which loading a device does not need: imported on first use
        from blocks import CapacitivePickoff, FullWaveRectifier
        ci = self.values["circuit"]
        k_dx = CapacitivePickoff(**ci["drive_pickoff"]).gain_V_per_m * abs(ci["drive_amp"]["gain"])
        return ci["reference"]["vref_V"] / (FullWaveRectifier(gain=ci["rectifier"]["gain"]).describing_gain() * k_dx)

    @property
    def drive_frequency_tc_Hz_per_K(self) -> float:
        """Slope of the drive resonance with die temperature at the reference temperature, in Hz/K.

        The central difference of :meth:`at` over +-0.5 K (the drive mode's stiffness and mass laws,
        both on the die); computed once per device content. A drive frequency read from a record
        becomes a die temperature change with it.
        """
        T = self.reference_temperature_C
        return _derived(self, "drive_frequency_tc_Hz_per_K", lambda: float(
            self.at(T + 0.5)["mechanics"]["f_drive_Hz"] - self.at(T - 0.5)["mechanics"]["f_drive_Hz"]))

    def _k3_from_rel(self) -> float:
        rel = self.values["mechanics"].get("duffing_k3_rel", 0.0)
        if rel == 0.0:
            return 0.0
        me = self.values["mechanics"]
        k_d = me["m_drive_kg"] * (2 * np.pi * me["f_drive_Hz"]) ** 2
        return rel * k_d / self.nominal_amplitude_m() ** 2


def _feedthrough_at(sp: dict, dT: float) -> dict:
    out = {k: v for k, v in sp.items() if k != "c_feedthrough_tc_per_K"}
    out["c_feedthrough_F"] = sp["c_feedthrough_F"] * (1 + sp.get("c_feedthrough_tc_per_K", 0.0) * dT)
    return out


def _merge(dst: dict, src: dict) -> None:
    for k, val in src.items():
        if isinstance(val, dict) and isinstance(dst.get(k), dict):
            _merge(dst[k], val)
        else:
            dst[k] = val


def load_device(path: str | Path) -> Device:
    """Load and validate a device file.

    Parameters
    ----------
    path : str or Path
        A device TOML, or a bare name found in ``scenarios/devices/`` (``fmvmg_a``).

    Returns
    -------
    Device

    Raises
    ------
    InputError
        Missing file, unknown key, bad value or a value without a source.
    """
    p = Path(path)
    if not p.suffix and not p.exists():
        p = DEVICES_DIR / f"{path}.toml"
    tree = load_toml(p)
    values = validate_tree(tree, DEVICE_SCHEMA, str(path), sourced=True)
    missing = _missing(values, DEVICE_SCHEMA)
    if missing:
        raise InputError(f"missing key(s) {missing}", str(path))
    check_pll_values(values, str(path))
    return Device(values, str(p))


def _missing(values: dict, schema: dict, prefix: str = "") -> list[str]:
    out = []
    for k, spec in schema.items():
        if k in ("name", "description", "*") or (prefix + k) in OPTIONAL_KEYS:
            continue
        if k not in values:
            out.append(prefix + k)
        elif isinstance(spec, dict):
            out += _missing(values[k], spec, prefix + k + ".")
    return out
