"""Shared helpers of the diagnosis tests: short simulated oven records with effects withheld."""

from __future__ import annotations

from pathlib import Path

from fmvmg_sim.diagnosis.parameters import apply_nominal
from fmvmg_sim.effects import EffectSet
from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.record import write_record
from fmvmg_sim.scenario import load_scenario
from fmvmg_sim.validation.cases import recorded

REPO = Path(__file__).resolve().parents[1]
NOMINAL = REPO / "scenarios" / "nominal_a.toml"

#: A unit off its nominal model in its values, its temperature laws and its data acquisition, each within its
#: tolerance: what the diagnosis must take for a unit without any library effect.
A_UNIT = {"q_sense_rel": 0.1, "quadrature_rel": -0.08, "demod_phase_mrad": 4.0, "f_modes_rel": 0.002,
          "q_drive_rel": -0.1, "q_gas_exponent": -0.5, "gbw_tc_per_K": 1e-3, "vref_tc_per_K": -1e-5,
          "quadrature_tc_per_K": -1e-3, "quadrature_offset_V": 0.01, "agc_effort_gain_rel": 0.03,
          "drive_frequency_offset_Hz": 0.05, "rate_offset_V": 0.005}

#: ~2.9 h oven: hold, cool at 1 K/min, hold, heat at 1 K/min, hold.
OVEN = """
[temperature]
start_C = 25.0
segments = [
  { hold_s = 1200.0 },
  { ramp_to_C = -10.0, rate_C_per_min = 1.0 },
  { hold_s = 1800.0 },
  { ramp_to_C = 50.0, rate_C_per_min = 1.0 },
  { hold_s = 1800.0 },
]
"""

#: ~2.9 h: a long hold, then the record's one ramp after the last fold's training window (76 % of the record).
LATE_RAMP = """
[temperature]
start_C = 25.0
segments = [
  { hold_s = 8500.0 },
  { ramp_to_C = 45.0, rate_C_per_min = 2.0 },
  { hold_s = 1400.0 },
]
"""


def oven_record(tmp: Path, name: str, effects: dict | None = None, seed: int = 1, rate_Hz: float = 1.0,
                noise: bool = True, theta: dict | None = None, profile: str = OVEN, duration_s: float = 10500.0):
    """Simulate the short oven profile (or ``profile``, a ``[temperature]`` table) with ``effects`` for the unit
    ``theta`` (knob deviations: its device, and its channels as recorded) and write ``tmp/name.csv``.

    Returns
    -------
    (Path, SimResult)
    """
    body = f"""
[scenario]
name = "{name}"
device_file = "{REPO / 'scenarios' / 'devices' / 'fmvmg_a.toml'}"
duration_s = {duration_s}
output_rate_Hz = {rate_Hz}
seed = {seed}
fidelity = "envelope"
[initial]
state = "steady"
[noise]
brownian = {str(noise).lower()}
electronic = {str(noise).lower()}
flicker = {str(noise).lower()}
quantization = {str(noise).lower()}
rate_random_walk = {str(noise).lower()}
""" + profile
    if effects:
        body += "[effects]\n" + "".join(
            f"{n} = {{ " + ", ".join(f"{k} = {v!r}" for k, v in ps.items()) + " }\n" for n, ps in effects.items())
    p = tmp / f"{name}.toml"
    p.write_text(body)
    scn = load_scenario(p)
    if theta:
        scn.device = EffectSet(scn.effects).apply_to_device(apply_nominal(scn.device_nominal, theta))
    res = run_envelope(scn, progress=False)
    rec = tmp / f"{name}.csv"
    write_record(rec, recorded(res.to_record(), theta or {}, scn.device_nominal.nominal_scale_factor_V_per_dps,
                               scn.device_nominal.reference_temperature_C))
    return rec, res
