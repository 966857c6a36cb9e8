"""The reference page of every scenario key (``docs/scenarios.md``), generated from the schemas.

Keys, accepted values and defaults come from the code (``scenario.SCENARIO_SCHEMA`` and
``DEFAULTS``, ``device.DEVICE_SCHEMA`` with the shipped ``fmvmg_a`` device's values,
``effects.MODELS``); units are read from the key names' suffixes; the one-line meanings are
:data:`MEANINGS`, which ``tests/test_docs.py`` checks cover every key. Regenerate the page with::

    python -m fmvmg_sim.schema_doc > docs/scenarios.md
"""

from __future__ import annotations

from .uncertainty import KNOBS

#: Unit suffixes of key names, longest first where one ends another.
UNIT_SUFFIXES = [
    ("_dps_per_sqrt_s", "deg/s/sqrt(s)"), ("_V_per_sqrtHz", "V/sqrt(Hz)"), ("_rad_per_K", "rad/K"),
    ("_mrad", "mrad"), ("_V_per_K", "V/K"), ("_Hz_per_K", "Hz/K"), ("_Hz_per_V", "Hz/V"), ("_F_per_m", "F/m"), ("_N_per_m3", "N/m^3"),
    ("_N_per_m", "N/m"), ("_per_K2", "1/K^2"), ("_per_K", "1/K"), ("_per_s", "1/s"), ("_per_V", "1/V"),
    ("_dps2", "(deg/s)^2"), ("_rad2", "rad^2"), ("_dps", "deg/s"), ("_Hz", "Hz"), ("_kg", "kg"), ("_rad", "rad"),
    ("_V", "V"), ("_F", "F"), ("_C", "degC"), ("_s", "s"), ("_m", "m"),
]

#: One-line meaning of every key, by dotted path (device keys without their ``device.`` prefix).
MEANINGS = {
    "scenario.name": "name of the run (default output folder `out/<name>`)",
    "scenario.description": "free text",
    "scenario.device_file": "device file: beside the scenario, or a shipped device (`fmvmg_a`, `fmvmg_b`, `dualmass_004`)",
    "scenario.duration_s": "simulated time (required)",
    "scenario.output_rate_Hz": "record sample rate (each sample is the mean over its interval)",
    "scenario.seed": "random seed of every noise source",
    "scenario.fidelity": "engine: `carrier` (every drive cycle), `envelope` (averaged), `auto` (envelope above 60 s)",
    "scenario.steps_per_cycle": "carrier engine: time steps per drive cycle",
    "scenario.envelope_step_s": "envelope engine: longest time step",
    "initial.drive_displacement_m": "drive displacement at t = 0 when starting at rest",
    "initial.state": "`rest` (a start-up from the small displacement) or `steady` (the loop's steady state)",
    "noise.brownian": "thermomechanical force noise on both modes",
    "noise.electronic": "white noise at the pickoff amplifiers",
    "noise.flicker": "1/f noise of the demodulation phase and of the output",
    "noise.quantization": "output quantisation of the DAQ",
    "noise.rate_random_walk": "rate random walk at the output",
    "name": "device name (written into records as `# device:`)",
    "description": "free text",
    "reference_temperature_C": "temperature at which the nominal values hold",
    "mechanics.f_drive_Hz": "drive-mode natural frequency",
    "mechanics.f_sense_Hz": "sense-mode natural frequency (before electrostatic softening)",
    "mechanics.m_drive_kg": "drive-mode effective mass",
    "mechanics.m_sense_kg": "sense-mode effective mass",
    "mechanics.m_coriolis_kg": "Coriolis mass (angular gain m_c / m_s)",
    "mechanics.q_drive": "drive-mode quality factor",
    "mechanics.q_sense": "sense-mode quality factor",
    "mechanics.quadrature_rate_dps": "quadrature stiffness coupling, as an equivalent rate",
    "mechanics.damping_coupling_rate_dps": "damping coupling, as an equivalent rate (an in-phase bias)",
    "mechanics.k_electrostatic_sense_N_per_m": "electrostatic spring of the sense mode (negative: softening)",
    "mechanics.duffing_k3_drive_N_per_m3": "cubic stiffness of the drive mode",
    "mechanics.duffing_k3_rel": "cubic stiffness relative to k x_0^2 (the `duffing` effect)",
    "thermal.tcf_linear_per_K": "frequency temperature coefficient, linear",
    "thermal.tcf_quadratic_per_K2": "frequency temperature coefficient, quadratic",
    "thermal.split_tcf_per_K": "difference of the two modes' TCF (mode-split drift)",
    "thermal.q_ted": "thermoelastic-damping Q at the reference temperature",
    "thermal.q_anchor": "anchor-loss Q",
    "thermal.q_gas_exponent": "gas-damping Q ~ T^-n exponent",
    "thermal.quadrature_tc_per_K": "quadrature temperature coefficient",
    "thermal.q_extra_tc_per_K": "extra Q drift, Q x exp(tc (T - T0)) (the `q_factor_drift` effect)",
    "thermal.q_curvature_per_K2": "curvature of the Q law: ln Q gains this times (T - T0)^2",
    "thermal.split_extra_Hz_per_K": "extra mode-split drift (the `mode_split_drift` effect)",
    "circuit.drive_pickoff.bias_V": "proof-mass bias of the drive pickoff",
    "circuit.drive_pickoff.dC_dx_F_per_m": "drive pickoff capacitance gradient",
    "circuit.drive_pickoff.c_feedback_F": "charge-amplifier feedback capacitance",
    "circuit.drive_amp.gain": "differential amplifier gain (block 1)",
    "circuit.drive_amp.gbw_Hz": "its gain-bandwidth product",
    "circuit.drive_amp.gbw_tc_per_K": "GBW temperature coefficient, at the board temperature",
    "circuit.drive_amp.offset_V": "output offset",
    "circuit.drive_amp.gain_tc_per_K": "gain temperature coefficient, at the board temperature",
    "circuit.phase_shifter.design_frequency_Hz": "frequency of exactly 90 degrees (block 2, RC all-pass)",
    "circuit.phase_shifter.trim_rad": "deliberate phase error at the design point",
    "circuit.phase_shifter.rc_tc_per_K": "RC time-constant temperature coefficient, at the board temperature",
    "circuit.rectifier.gain": "full-wave rectifier gain (block 3)",
    "circuit.rectifier.offset_tc_V_per_K": "rectifier offset drift, at the board temperature",
    "circuit.amplitude_lpf.f_c_Hz": "amplitude low-pass corner (block 4, 2nd order)",
    "circuit.reference.vref_V": "amplitude set-point Vref (block 6)",
    "circuit.reference.vref_tc_per_K": "Vref temperature coefficient, at the board temperature",
    "circuit.pi.kp": "PI proportional gain (block 7)",
    "circuit.pi.ki_per_s": "PI integral gain",
    "circuit.pi.u_min_V": "PI output lower limit (anti-windup)",
    "circuit.pi.u_max_V": "PI output upper limit (anti-windup)",
    "circuit.modulator.carrier": "`normalized` (fixed-amplitude carrier) or `pickoff` (the phase-shifted pickoff as is)",
    "circuit.modulator.vdac_V": "carrier amplitude (block 8)",
    "circuit.modulator.k_per_V": "multiplier scale",
    "circuit.comb_drive.vdc_V": "DC bias of the comb drive (block 9)",
    "circuit.comb_drive.dC_dx_F_per_m": "comb capacitance gradient, per side (block 10)",
    "circuit.comb_drive.topology": "`push-pull` or `single-sided` drive",
    "circuit.comb_drive.asymmetry": "relative comb mismatch (DC force and the 2-omega term)",
    "circuit.sense_pickoff.bias_V": "proof-mass bias of the sense pickoff",
    "circuit.sense_pickoff.dC_dx_F_per_m": "sense pickoff capacitance gradient",
    "circuit.sense_pickoff.c_feedback_F": "charge-amplifier feedback capacitance",
    "circuit.sense_pickoff.c_feedthrough_F": "drive-to-sense feedthrough capacitance",
    "circuit.sense_pickoff.sign": "wiring polarity of the sense output",
    "circuit.sense_pickoff.c_feedthrough_tc_per_K":
        "feedthrough temperature coefficient (`feedthrough`), at the board temperature",
    "circuit.sense_amp1.gain": "first sense amplifier gain (block 11)",
    "circuit.sense_amp1.gbw_Hz": "its gain-bandwidth product",
    "circuit.sense_amp1.gbw_tc_per_K": "GBW temperature coefficient, at the board temperature",
    "circuit.sense_amp1.offset_V": "output offset",
    "circuit.sense_amp1.gain_tc_per_K": "gain temperature coefficient, at the board temperature",
    "circuit.sense_amp2.gain": "second sense amplifier gain (block 12)",
    "circuit.sense_amp2.gbw_Hz": "its gain-bandwidth product",
    "circuit.sense_amp2.gbw_tc_per_K": "GBW temperature coefficient, at the board temperature",
    "circuit.sense_amp2.offset_V": "output offset",
    "circuit.sense_amp2.gain_tc_per_K": "gain temperature coefficient, at the board temperature",
    "circuit.demodulator.k_per_V": "demodulator multiplier scale (block 13)",
    "circuit.demodulator.phase_trim": "reference phase trim: `auto` (trimmed at 25 C) or a value in rad",
    "circuit.demodulator.phase_tc_rad_per_K":
        "demodulation phase drift (`demod_phase_drift`), at the board temperature",
    "circuit.output_lpf.f_c_Hz": "output low-pass corner (block 14, 2nd order)",
    "circuit.output_lpf.gain": "output low-pass gain",
    "circuit.sense.topology": "sense chain: `open-loop` (paper 000) or `force-rebalance` (the rate read from the "
                              "feedback voltage; docs/model.md, Closed-loop sense)",
    "circuit.rebalance.dC_dx_F_per_m": "force-rebalance comb capacitance gradient per side (push-pull)",
    "circuit.rebalance.vdc_V": "DC bias on the force-rebalance combs",
    "circuit.rebalance.k_mod_per_V": "remodulating multiplier scale",
    "circuit.rebalance.filter_f_c_Hz": "corner of the rate loop's demodulation low-pass (two 2nd-order sections)",
    "circuit.rebalance.kp": "rate-loop proportional gain (>= 0)",
    "circuit.rebalance.ki_per_s": "rate-loop integral gain (> 0)",
    "circuit.rebalance.kd_s": "rate-loop derivative gain (>= 0): damps the sense mode's ringing at the split",
    "circuit.quadrature_control.enabled": "close the quadrature loop (DC quadrature-tuning electrodes)",
    "circuit.quadrature_control.dk_dV_N_per_m_per_V": "tuning electrodes' coupling stiffness per volt",
    "circuit.quadrature_control.filter_f_c_Hz": "corner of the quadrature loop's demodulation low-pass (two 2nd-order sections)",
    "circuit.quadrature_control.kp": "quadrature-loop proportional gain (>= 0)",
    "circuit.quadrature_control.ki_per_s": "quadrature-loop integral gain (> 0)",
    "circuit.drive.topology": "drive loop: `self-oscillating` (paper 000's phase-shifter loop, the default) or `pll` "
                              "(docs/model.md, PLL drive)",
    "circuit.pll.f_free_offset_Hz": "PLL oscillator's free-running frequency above the drive resonance at the "
                                    "reference temperature (default 0)",
    "circuit.pll.f_free_tc_per_K": "its temperature coefficient, at the board temperature (default 0: a crystal-clocked NCO)",
    "circuit.pll.k_vco_Hz_per_V": "oscillator tuning gain, > 0 (default 50)",
    "circuit.pll.k_vco_tc_per_K": "its temperature coefficient, at the board temperature (default 0)",
    "circuit.pll.kp": "PLL loop filter's proportional gain, V/V (default 1)",
    "circuit.pll.ki_per_s": "its integral gain (default 60)",
    "circuit.pll.v_min_V": "tuning range, lower end (default -10)",
    "circuit.pll.v_max_V": "tuning range, upper end (default 10)",
    "circuit.pll.pd_lpf_f_c_Hz": "phase detector's low-pass corner, 2nd order (default 2000)",
    "circuit.pll.pd_trim": "phase detector's reference trim in rad, or `auto`: the drive chain's phase at the "
                           "reference temperature (default)",
    "noise.sense_input_V_per_sqrtHz": "white noise density at the sense front end",
    "noise.drive_input_V_per_sqrtHz": "white noise density at the drive front end",
    "noise.flicker_phase_rad2": "1/f demodulation-phase noise coefficient",
    "noise.flicker_output_dps2": "1/f output offset noise coefficient",
    "noise.rate_random_walk_dps_per_sqrt_s": "rate random walk coefficient",
    "noise.quantization_lsb_V": "DAQ quantisation step",
}

MEANINGS.update({f"tolerance.{k.name}": k.meaning for k in KNOBS})
MEANINGS["tolerance.law_curvature_per_K2"] = ("how far the laws may be off beyond the temperatures a calibration saw "
                                              "(times the squared distance, relative to each channel)")

#: The profile tables: their start key and unit suffix.
PROFILES = [("temperature", "start_C", "C", "degC", False), ("rate", "start_dps", "dps", "deg/s", True),
            ("vref", "start_factor", "factor", "x Vref", False)]


def unit_of(key: str) -> str:
    """The unit a key name carries in its suffix (``"1"`` for a plain number).

    Parameters
    ----------
    key : str

    Returns
    -------
    str
    """
    leaf = key.rsplit(".", 1)[-1]
    for suffix, unit in UNIT_SUFFIXES:
        if leaf.endswith(suffix):
            return unit
    return "1"


def accepted(spec) -> str:
    """What a schema leaf accepts, in words.

    Parameters
    ----------
    spec : Num, Choice, Bool or Text

    Returns
    -------
    str
    """
    from .schema import Bool, Choice, Num
    if isinstance(spec, Bool):
        return "true, false"
    if isinstance(spec, Choice):
        return ", ".join(f'"{o}"' for o in spec.options)
    if isinstance(spec, Num):
        if spec.lo is not None and spec.hi is not None:
            rng = f"{spec.lo:g} .. {spec.hi:g}"
        elif spec.positive and spec.hi is not None:
            rng = f"> 0, <= {spec.hi:g}"
        elif spec.positive:
            rng = "> 0"
        elif spec.lo is not None:
            rng = f">= {spec.lo:g}"
        elif spec.hi is not None:
            rng = f"<= {spec.hi:g}"
        else:
            rng = "number"
        if spec.integer:
            rng += ", integer"
        if spec.allow:
            rng = " or ".join([*(f'"{a}"' for a in spec.allow), rng])
        return rng
    return "text"


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"' if value else '""'
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _leaves(schema: dict, prefix: str = ""):
    for key, spec in schema.items():
        if isinstance(spec, dict):
            yield from _leaves(spec, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", spec


def all_keys() -> list[str]:
    """Every key the page documents (device keys without their ``device.`` prefix).

    Returns
    -------
    list of str
    """
    from .device import DEVICE_SCHEMA
    from .scenario import SCENARIO_SCHEMA
    return [k for k, _ in _leaves(SCENARIO_SCHEMA)] + [k for k, _ in _leaves(DEVICE_SCHEMA)]


def _row(*cells) -> str:
    return "| " + " | ".join(cells) + " |"


def markdown() -> str:
    """The whole ``docs/scenarios.md`` page.

    Returns
    -------
    str
    """
    from .device import DEVICE_SCHEMA, OPTIONAL_KEYS, load_device
    from .effects import MODELS
    from .paths import devices_dir
    from .scenario import DEFAULTS, SCENARIO_SCHEMA
    dev = load_device(devices_dir() / "fmvmg_a.toml").values
    lines = [
        "# Scenario keys",
        "",
        "<!-- generated by `python -m fmvmg_sim.schema_doc > docs/scenarios.md`; tests/test_docs.py checks it -->",
        "",
        "A scenario is a TOML file (the shipped ones are in `scenarios/`; `fmvmg run NAME` runs one by name).",
        "Every key below may also be given on the command line as `--set KEY=VALUE` (e.g.",
        "`--set scenario.duration_s=10 --set circuit.pi.kp=100`), and an unknown key, a wrong type or a value",
        "outside its range is refused (exit 2) with the key named. Units are in the key names.",
        "",
    ]
    for table in ("scenario", "initial", "noise"):
        lines += [f"## [{table}]", "", _row("key", "accepts", "unit", "default", "meaning"), _row(*["---"] * 5)]
        for key, spec in _leaves(SCENARIO_SCHEMA[table], f"{table}."):
            leaf = key.split(".", 1)[1]
            default = DEFAULTS[table].get(leaf)
            unit = "-" if not type(spec).__name__ == "Num" else unit_of(key)
            lines.append(_row(f"`{leaf}`", accepted(spec), unit, "required" if default is None else _fmt(default),
                              MEANINGS[key]))
        lines.append("")
    lines += ["## Profiles: [temperature], [rate], [vref]", "",
              "Each is a start value and a list of segments, or a list of `[t_s, value]` points (linear between",
              "them, the first at t = 0). Without the table the value stays at its start.", "",
              _row("table", "start key (default)", "unit", "segment forms"), _row(*["---"] * 4)]
    for table, start, suffix, unit, sines in PROFILES:
        forms = [f"`{{ hold_s }}`", f"`{{ ramp_to_{suffix}, rate_{suffix}_per_min }}`",
                 f"`{{ ramp_to_{suffix}, duration_s }}`", f"`{{ step_to_{suffix} }}`"]
        if sines:
            forms.append("`{ sine_amplitude_dps, sine_frequency_Hz, duration_s [, phase_deg] }`")
        default = "1" if table == "vref" else "0"
        lines.append(_row(f"`[{table}]`", f"`{start}` ({default})", unit, "; ".join(forms)))
    lines += ["", "For example `[temperature]` `start_C = 25.0`, "
              "`segments = [{hold_s = 3600}, {ramp_to_C = 60.0, rate_C_per_min = 1.0}]`.", ""]
    lines += ["## [effects]", "",
              "Unmodelled effects switched on in the simulation (the vocabulary of the diagnosis report). A",
              "parameter left out takes the middle of its typical range; values outside the physical bounds are",
              "refused. For example `[effects]` `thermal_lag = { tau_s = 600 }`.", "",
              _row("effect", "parameter", "unit", "physical bounds", "typical range (default: its middle)"),
              _row(*["---"] * 5)]
    for name, params in MODELS.items():
        for pname, p in params.items():
            sign = ", either sign" if p.signed else ""
            lines.append(_row(f"`{name}`", f"`{pname}`", p.unit, f"{p.lo:g} .. {p.hi:g}",
                              f"{p.prior[0]:g} .. {p.prior[1]:g}{sign}"))
    lines += ["", "## [device.*] and [circuit.*]", "",
              "Overrides of any value of the device file. `[circuit.pi]` is short for `[device.circuit.pi]`",
              "(likewise `--set circuit.pi.kp=100`). The defaults shown are those of the shipped `fmvmg_a` device",
              "(paper 000's configuration A); a device file gives every value with its source (`[S]` sourced, `[D]`",
              "derived, `[E]` estimate). Keys marked optional may be left out of a device file (they default to 0).", ""]
    groups: dict[str, list] = {}
    for key, spec in _leaves(DEVICE_SCHEMA):
        groups.setdefault(key.rsplit(".", 1)[0] if "." in key else "", []).append((key, spec))
    for group, items in groups.items():
        title = f"[device.{group}]" if group else "[device]"
        lines += [f"### {title}", ""]
        if group == "tolerance":
            lines += ["What the values above are not known to better than, for one unit and its data acquisition: the",
                      "diagnosis calibrates each knob within its tolerance (unit values, temperature laws, channel",
                      "offsets and gains; docs/diagnosis_guide.md), the diagnosis benchmark draws units uniformly within",
                      "them, and 0 holds a knob at its nominal value. Each is a deviation in the unit its name carries.",
                      ""]
        lines += [_row("key", "accepts", "unit", "fmvmg_a", "meaning"), _row(*["---"] * 5)]
        for key, spec in items:
            node = dev
            for part in key.split("."):
                node = node.get(part) if isinstance(node, dict) else None
            value = "0 (optional)" if node is None and key in OPTIONAL_KEYS else _fmt(node)
            if node is None and key.rsplit(".", 1)[0] in OPTIONAL_KEYS:  # a key of an optional table
                value = "(optional)"
            unit = "-" if type(spec).__name__ != "Num" else unit_of(key)
            lines.append(_row(f"`{key.rsplit('.', 1)[-1]}`", accepted(spec), unit, value, MEANINGS[key]))
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


if __name__ == "__main__":
    import sys
    sys.stdout.write(markdown())
