"""Records are bit for bit what they were: SHA-256 of short runs of every shipped scenario in both engines.

A change to the code's structure must not change a record. The table below holds the SHA-256 of the
record channels, internal channels and metadata of a short run of each shipped scenario (and of one
scenario with every time-history effect and a fast temperature ramp) in each engine. When the physics or
the numerics change on purpose, regenerate it with ``python -m tests.test_records_unchanged`` and say in
the commit message what changed. The digests hold for the compiled roll-outs on one platform (numpy,
scipy, CasADi and gcc versions, CPU); runs in CasADi's virtual machine draw their noise differently and
are skipped.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np
import pytest

from fmvmg_sim.carrier.engine import run_carrier
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

SHA256 = {
    ("force_rebalance_rate", "carrier"): "403417b9093b8b4f469c86be9ec16b4477a39c1bc7feb9128b2820b69e60531f",
    ("force_rebalance_rate", "envelope"): "df215b7f38c9c7809c398df2e014b9c6b57d94e063831d3bf1d7f4317bc6c0d5",
    ("nominal_a", "carrier"): "f7e8ed1d1d959812e4dcec044e3303b9ca7f82c066af88a80b7c64d38f1864d3",
    ("nominal_a", "envelope"): "068754c5212b04c15be0bd2e3aaf9fe5bffe5a6dbd1b55c1316053257f2cf669",
    ("nominal_a_stable_electronics", "carrier"): "eb49e50ec9e43bcf62f2a25b8b18ac07edcb59cfac81088b4b8b7d2eaf2bccb3",
    ("nominal_a_stable_electronics", "envelope"): "76fac29a6bade3494873640dcfc098440ce7990e90889d55f1adfe4dc8dab9a4",
    ("oven_000", "carrier"): "ff0b72547ab22d1d128606c62d8023ecdbcdb1eedf35601f38ba7eed34da0db5",
    ("oven_000", "envelope"): "de962f4c7c57b2a4829e7c968824467627546b5f1e68202456f15eb974957f93",
    ("oven_004", "carrier"): "8d4b0e71804f274e4cab388c2596c98b787ccffcb594b1c12392f1691ec3efb4",
    ("oven_004", "envelope"): "e4bd826bef80114b5e03646f4be7f574b296122d8c67a46ab343df41808ff7cf",
    ("pll_oven_ramp", "carrier"): "f32e99f26f9a54735730793d32b60e8ffcb482fecfd38ee488b1ce3ce6866b89",
    ("pll_oven_ramp", "envelope"): "ee87bbe1f5cba4e04dcdfe9b19a5038495e5f5e399f683df248f7b45ac3c5f03",
    ("pll_startup", "carrier"): "70b5a5443b8da963b90ceeea888ad228e05cf68ce2d7be44b7876da4b32e67c8",
    ("pll_startup", "envelope"): "6b2ccd4dbf62091d06cddb7b7f50fbc6efca821083fd7cf49536954f031d6961",
    ("population_oven", "carrier"): "210f56b2a8f06501171dc3e801be76778f88c2b263eb6285e7414856d5cd1bcc",
    ("population_oven", "envelope"): "9c88e8b3b5b6008225d95b1416c5846734a5425f5b39a1ab62273d20eadd1900",
    ("rate_steps", "carrier"): "67fa94a9178f82356837eccf9ee176d522c97b5484bd5c6da013f4787275391a",
    ("rate_steps", "envelope"): "6684a76835fe7aa3befaa3f727e5532a464763a36f63ff25b1798b6dee3b295a",
    ("rate_table", "carrier"): "91c790cd322ecea849a052211bd74f7581ab33d5b1ce9124139ec39c52efc669",
    ("rate_table", "envelope"): "0b0801b7b0e6f311bebd47a4b56fe325012deaa1bee8161a1c15b011c6090b82",
    ("startup", "carrier"): "3eb6fc051bec1d692b9a33a485a6aecd7926e3d86fddf6f3afa4f96202785eac",
    ("startup", "envelope"): "512acfac9e980be75dc0e46c66321b50e1a6baceda7cde5c45b1050e3a7154ac",
    ("static_25C", "carrier"): "0b70da4638bbb4c96286e3c805fdc4b1521a7726bbd6ee51fbba79d512c5e1b3",
    ("static_25C", "envelope"): "aeb39e2a7e79561f1e98cf2695ac2a9cd8b106c1c8633613f7fde9d20ee4b0e6",
    ("tune_startup", "carrier"): "693fde8a6722d4548fe6d06e6c281bf4929f915065dc06fbf419b478361b26df",
    ("tune_startup", "envelope"): "c237b60509475615d8917cd17af91a803a7957ff18aacee3d2acf32d56858733",
    ("tune_step", "carrier"): "62be746fab3ae692a91bcbf23835f391370d5cc29550f3e7b5fbd9cfa0dddb18",
    ("tune_step", "envelope"): "229ea846ae06bc51dd27b97b5d1360c3d425949ebc9ab8f8531624e0742d4019",
    ("effects_ramp", "carrier"): "ae6edf33c7b1b3c4a8be69c20fdc577f50e6aa653f0f698b8ada149a8f060dc6",
    ("effects_ramp", "envelope"): "99ce4b8661e62368bc1ba46d137f8cb562eace034ee7c9dabbdaf8c8f9e1ea53",
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
    assert (name, engine) in SHA256, f"no stored digest for {name} in the {engine} engine; regenerate the table"
    assert digest(res) == SHA256[(name, engine)], (
        f"the {engine} engine's record of {name} changed; if on purpose, regenerate the table "
        "(python -m tests.test_records_unchanged)")


def main() -> int:
    """Print the digest table for pasting into :data:`SHA256`."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        print("SHA256 = {")
        for name in _cases():
            for engine in ("carrier", "envelope"):
                print(f'    ("{name}", "{engine}"): "{digest(_run(name, engine, Path(tmp)))}",')
        print("}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
