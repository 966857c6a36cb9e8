"""Records are bit for bit what they were: SHA-256 of short runs of every shipped scenario in both engines.

A change to the code's structure must not change a record. The table below holds the SHA-256 of the
record channels, internal channels and metadata of a short run of each shipped scenario (and of one
scenario with every time-history effect and a fast temperature ramp) in each engine. When the physics or
the numerics change on purpose, regenerate it with ``python -m tests.test_records_unchanged`` and say in
the commit message what changed. The digests hold for the compiled roll-outs on one platform (numpy,
scipy, CasADi and C compiler versions, CPU: the roll-outs are built for the CPU they run on, and numpy
dispatches its transcendental functions by the CPU's vector extensions), named by :data:`PLATFORM`; on
another platform the test is skipped naming both, and regenerating the table there makes it that
platform's guard. Runs in CasADi's virtual machine draw their noise differently and are skipped.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.compiled import _cpu_id
from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.paths import shipped_scenarios
from fmvmg_sim.scenario import load_scenario
from tests.conftest import REPO, scenario_text

#: Simulated seconds and output rate of the carrier runs (a few compiled chunks, one temperature key each).
CARRIER_SET = ["scenario.duration_s=0.05", "scenario.output_rate_Hz=2000"]
#: Longest simulated span of the envelope runs (s): the scenario's own output rate and envelope step.
ENVELOPE_MAX_S = 60.0

#: A scenario the shipped ones do not cover in a short run: the temperature ramping fast (a thermal lag
#: puts the die off the board), every time-history effect and every temperature-law effect switched on.
EFFECTS_BODY = """
[rate]
start_dps = 0.0
segments = [ { hold_s = 0.02 }, { step_to_dps = 30.0 }, { hold_s = 10.0 },
             { sine_amplitude_dps = 5.0, sine_frequency_Hz = 2.0, duration_s = 20.0 } ]
[vref]
segments = [ { hold_s = 15.0 }, { step_to_factor = 1.05 } ]
[effects]
thermal_lag = { tau_s = 20.0, offset_K = 0.5 }
thermal_hysteresis = { quad_rel = 0.01, width_K = 2.0 }
temperature_rate = { g_dph_per_K_per_min = 50.0 }
demod_phase_drift = { kappa_urad_per_K = 100.0 }
quadrature_drift = { beta_per_K = 0.002 }
q_factor_drift = { q_tc_per_K = 0.005 }
mode_split_drift = { split_Hz_per_K = 0.03 }
feedthrough = { c_ft_fF = 5.0, tc_per_K = 2e-4 }
duffing = { k3_rel = 5e-4 }
flicker_noise = { h_phase_rad2 = 2e-9, h_output_dps2 = 5e-5 }
reference_drift = { vref_tc_per_K = 5e-5, rectifier_mV_per_K = 1.0 }
stress_relaxation = { quad_rel = 0.01, tau_h = 0.01 }
quantization = { lsb_V = 1e-3 }
"""
EFFECTS_TEMPERATURE = ("start_C = 20.0\nsegments = [ { hold_s = 0.01 }, { ramp_to_C = 40.0, rate_C_per_min = 60.0 },"
                       " { ramp_to_C = 30.0, rate_C_per_min = 60.0 } ]")

def platform_key() -> str:
    """What the digests depend on besides the code: machine, CPU (model and flags, hashed), C compiler, numpy,
    scipy and CasADi versions."""
    import casadi
    import scipy
    cc = shutil.which(os.environ.get("CC") or "gcc")
    cc_version = ""
    if cc:
        out = subprocess.run([cc, "-dumpfullversion"], capture_output=True, text=True)
        cc_version = out.stdout.strip() or out.stderr.strip()[:40]
    cpu = hashlib.sha256(_cpu_id().encode()).hexdigest()[:12]
    return (f"{platform.machine()} cpu {cpu} cc {cc_version} numpy {np.__version__} scipy {scipy.__version__} "
            f"casadi {casadi.__version__}")


#: The platform the table below was made on (:func:`platform_key`).
PLATFORM = "x86_64 cpu f84b97a458c3 cc 12.2.0 numpy 2.4.6 scipy 1.17.1 casadi 3.8.2"
SHA256 = {
    ("force_rebalance_rate", "carrier"): "62699b72593b99848f114e93fc843f2664ecbf2ddf028d429b158ee8c95432bc",
    ("force_rebalance_rate", "envelope"): "7d6b31c2303b02456fe41bdbdf8470621129ba6ef81333e0cae47bde2490042b",
    ("nominal_a", "carrier"): "42c7f5b7d3a081d49f2356e0c6e3ab4b507e79e5d45482053ce0fb1fc515ea5b",
    ("nominal_a", "envelope"): "63622ccdaa88d31593d0e9fc7181bc3fbdbc4cb30e5b30b31fb1385d796ff24e",
    ("nominal_a_stable_electronics", "carrier"): "e589abc40662419068853fb961f90114507b6e01d4851980dbfc18941f06feed",
    ("nominal_a_stable_electronics", "envelope"): "549df3cebde33d24aa30611ffab4a226c79ecc38e896624781fb2a6b07eb7486",
    ("oven_000", "carrier"): "59ee74b58cdcbcc8cf0ac399f09ab1d03a56e126ad21649c903ffe43a256d4fd",
    ("oven_000", "envelope"): "5c1a88bebbd12bf0bed4007b497510db94278e4d19efb98be684e1bcac0dadac",
    ("oven_004", "carrier"): "292b84946b10f07531e5079237ecae37640b880eb4dcd5dd246917df1e6e52a4",
    ("oven_004", "envelope"): "6548dabfe2afb19921da01299e14931cde7e3e7b5f9cd63f755e36baf3bd602a",
    ("pll_oven_ramp", "carrier"): "e389177c8e4e9b4782d7437c877fe313109893276a65c50b47727f4244f5ee56",
    ("pll_oven_ramp", "envelope"): "305b68bdad4eb0573a3cc7818c1fd63abcfeb85a810a1b6254ca64c60aac63c5",
    ("pll_startup", "carrier"): "47b446eb05da9ae64b1527778be30713b6f721fdb6473178fb9244d01d9e971a",
    ("pll_startup", "envelope"): "3b25ccf87df283ad53b3b161374355d435e11917872fdcbf09de604108b1ea2c",
    ("population_oven", "carrier"): "b912f7c1c5b627650db0629a801b9cc6d74f6a253e63cc749b71036156cee72e",
    ("population_oven", "envelope"): "27ee8de9368d00c02649ad82f84fe3f13a722979607c7e85c8bb2adacd9385dd",
    ("rate_steps", "carrier"): "5c9dcd620d400b044ada914841c2fdd0078bfa5678f5b9ebb52e57b89b48d59c",
    ("rate_steps", "envelope"): "c989b9a40e4d559a58ae5dbfbb7b62020536c0754b2b06ef8fe8824c7123b757",
    ("rate_table", "carrier"): "07ef696ae503d6930a790575cbb862820200ed81364d325c3f150b625a32ad41",
    ("rate_table", "envelope"): "4f5630aa72fcab792dcec64902ba0f415b744e7552d0a45d6d6e5186599e6137",
    ("startup", "carrier"): "993bda2854070d9a1a057ebbdd1fe1b8f5fb51c6c005da793341b31b6ac7f645",
    ("startup", "envelope"): "18d357d5a98fde2084c661fbd3dd6ff564c482f848b9417f70f2c0fb633b0a6c",
    ("static_25C", "carrier"): "f6ea688debcc57883401fb4b674159391c1d7daef0ec781fc0132fd2e1fb80c8",
    ("static_25C", "envelope"): "7b2ddfee879820fadc886a3047e77a936db8612a5c8ddf143f1d0ae8f9fc314a",
    ("tune_startup", "carrier"): "43f06a15eb8d7670c05786d1b26eb0fae0bd951363db88ced0ff94c4930c4ac0",
    ("tune_startup", "envelope"): "9caf0bb102f4f7fc861484d23186031c992c2fb969bc105cbf0326adc5781977",
    ("tune_step", "carrier"): "963d6b89475e90c8d3224b28cd0aa94253255f51221693980d51e9355169d44c",
    ("tune_step", "envelope"): "067f99aac38e69d10dbc72f2cfc0a359faf468ad6c12aa85d18f8066c0277814",
    ("effects_ramp", "carrier"): "cfe32a308db63f514a8a4d8e919d3c977a394909793ae470070b672a192eaebe",
    ("effects_ramp", "envelope"): "c85980020053fbef3a0faa96b341fa95cc14399a6c6b58dfeeab5bb6a271e5e8",
}


def _effects_scenario(tmp: Path) -> Path:
    path = tmp / "effects_ramp.toml"
    path.write_text(scenario_text("effects_ramp", duration_s=40.0, output_rate_Hz=1000.0, state="steady",
                                  temperature=EFFECTS_TEMPERATURE, fidelity="envelope", noise=True, seed=5)
                    + EFFECTS_BODY)
    return path


def _cases() -> list[str]:
    return sorted(shipped_scenarios()) + ["effects_ramp"]


def _run(name: str, engine: str, tmp: Path):
    path = _effects_scenario(tmp) if name == "effects_ramp" else REPO / "scenarios" / f"{name}.toml"
    if engine == "carrier":
        return run_carrier(load_scenario(path, fidelity="carrier", overrides=CARRIER_SET), progress=False)
    scn = load_scenario(path, fidelity="envelope")
    span = min(scn.duration_s, ENVELOPE_MAX_S)
    return run_envelope(load_scenario(path, fidelity="envelope", overrides=[f"scenario.duration_s={span}"]),
                        progress=False)


def digest(res) -> str:
    """SHA-256 of a result's channels (record and internal, by name) and metadata.

    Parameters
    ----------
    res : SimResult

    Returns
    -------
    str
    """
    h = hashlib.sha256()
    for group in (res.channels, res.internal):
        for key in sorted(group):
            h.update(key.encode())
            h.update(np.ascontiguousarray(group[key], dtype=np.float64).tobytes())
    for key in sorted(res.metadata):
        h.update(f"{key}={res.metadata[key]}".encode())
    return h.hexdigest()


@pytest.mark.parametrize("engine", ["carrier", "envelope"])
@pytest.mark.parametrize("name", _cases())
def test_record_unchanged(name, engine, tmp_path):
    res = _run(name, engine, tmp_path)
    if not res.info["compiled"]:
        pytest.skip("no C compiler: the virtual machine's roll-out draws its noise differently")
    if platform_key() != PLATFORM:
        pytest.skip(f"digests made on {PLATFORM}, this is {platform_key()}: regenerate the table here "
                    "(python -m tests.test_records_unchanged) to guard records on this platform")
    assert (name, engine) in SHA256, f"no stored digest for {name} in the {engine} engine; regenerate the table"
    assert digest(res) == SHA256[(name, engine)], (
        f"the {engine} engine's record of {name} changed; if on purpose, regenerate the table "
        "(python -m tests.test_records_unchanged)")


def main() -> int:
    """Print the platform and digest table for pasting over :data:`PLATFORM` and :data:`SHA256`."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        print(f'PLATFORM = "{platform_key()}"')
        print("SHA256 = {")
        for name in _cases():
            for engine in ("carrier", "envelope"):
                print(f'    ("{name}", "{engine}"): "{digest(_run(name, engine, Path(tmp)))}",')
        print("}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
