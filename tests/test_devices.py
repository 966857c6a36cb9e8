"""The three shipped devices: loadable, every number sourced, and physically what their papers say."""

import numpy as np
import pytest

from fmvmg_sim.averaged import scale_factor_V_per_dps, steady_state
from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.device import DEVICES_DIR, load_device
from fmvmg_sim.diagram import build_diagram
from fmvmg_sim.scenario import load_scenario

DEVICES = {"fmvmg_a": (30740.0, 30886.0), "fmvmg_b": (9609.6, 9615.4), "dualmass_004": (3484.0, 3468.0)}


@pytest.mark.parametrize("name", sorted(DEVICES))
def test_device_modes_and_positive_scale_factor(name):
    dev = load_device(name)
    f_d, f_s = DEVICES[name]
    assert dev.values["mechanics"]["f_drive_Hz"] == f_d and dev.values["mechanics"]["f_sense_Hz"] == f_s
    dg = build_diagram(dev, 25.0)
    ss = steady_state(dg)
    assert ss.f_Hz == pytest.approx(f_d, rel=1e-5)  # shifted by the sense back-action, ripple and phase errors
    assert scale_factor_V_per_dps(dg) > 0
    assert dg.pi.u_min_V < ss.agc_effort_V < dg.pi.u_max_V


def test_config_b_has_25x_the_gain_and_a_4p7_degree_sense_phase():
    """physics.md key points: at Q_s = 1e4 config B gives 25x the gain and a 4.7 degree sense phase."""
    a, b = build_diagram(load_device("fmvmg_a"), 25.0), build_diagram(load_device("fmvmg_b"), 25.0)
    ratio = scale_factor_V_per_dps(b) / scale_factor_V_per_dps(a)
    assert ratio == pytest.approx(146.0 / 5.8, rel=0.03)
    w = steady_state(b).omega_rad_s
    ws = 2 * np.pi * b.resonator.f_sense_Hz
    phase = np.degrees(np.arctan2(ws * w / b.resonator.q_sense, ws ** 2 - w ** 2))
    assert phase == pytest.approx(4.7, abs=0.1)


@pytest.mark.parametrize("name", ["fmvmg_b", "dualmass_004"])
def test_other_devices_run_at_carrier_level(make_scenario, name):
    path = make_scenario(duration_s=0.3, output_rate_Hz=200.0)
    scn = load_scenario(path, overrides=[f'scenario.device_file="{DEVICES_DIR / (name + ".toml")}"'])
    res = run_carrier(scn, progress=False)
    ss = steady_state(build_diagram(scn.device, 25.0))
    assert np.nanmean(res["drive_frequency_Hz"][20:]) == pytest.approx(ss.f_Hz, abs=0.02)
    assert np.mean(res["agc_effort_V"][20:]) == pytest.approx(ss.agc_effort_V, rel=5e-3)


def test_every_device_number_has_a_source():
    import tomllib
    for path in DEVICES_DIR.glob("*.toml"):
        tree = tomllib.loads(path.read_text())

        def walk(node, where):
            for k, v in node.items():
                if isinstance(v, dict) and "value" in v:
                    assert v.get("source", "")[:3] in ("[S]", "[D]", "[E]"), f"{path.name}: {where}{k}"
                elif isinstance(v, dict):
                    walk(v, f"{where}{k}.")
        walk(tree, "")


@pytest.mark.parametrize("name", ["fmvmg_b", "dualmass_004"])
def test_envelope_agrees_with_carrier_for_the_other_devices(make_scenario, name):
    """Small splits make the sense back-action and, at 3.5 kHz, the rectifier ripple matter; both are modelled."""
    from fmvmg_sim.envelope.engine import run_envelope
    path = make_scenario(duration_s=1.0, output_rate_Hz=100.0)
    over = [f'scenario.device_file="{DEVICES_DIR / (name + ".toml")}"']
    c = run_carrier(load_scenario(path, overrides=over), progress=False)
    e = run_envelope(load_scenario(path, overrides=over, fidelity="envelope"), progress=False)
    for k, tol in (("agc_effort_V", 5e-3), ("quadrature_V", 5e-3)):
        assert np.mean(e[k][50:]) == pytest.approx(np.mean(c[k][50:]), rel=tol), k
    assert np.mean(e["drive_frequency_Hz"][50:]) == pytest.approx(np.nanmean(c["drive_frequency_Hz"][50:]), abs=0.01)
    sf = c.info["nominal_scale_factor_V_per_dps"]
    assert np.mean(e["rate_V"][50:]) / sf == pytest.approx(np.mean(c["rate_V"][50:]) / sf, abs=0.02)
