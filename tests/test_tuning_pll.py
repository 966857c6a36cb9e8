"""``fmvmg tune --loop pll``: the linearised phase loop against its closed form and against the envelope engine."""

import json

import control
import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.device import load_device
from fmvmg_sim.pll_drive import build_pll_drive, pll_steady_state
from fmvmg_sim.tuning.pll import check_pll_gains, design_pll_gains, loop_transfer, margins, phase_plant


@pytest.fixture(scope="module")
def device():
    return load_device("fmvmg_a").with_overrides({"circuit": {"drive": {"topology": "pll"}}}, "test")


def test_phase_plant_is_the_resonators_phase_lag(device):
    """Near lock the detector reads -V/(s + 1/tau_d) per rad/s: its DC gain is -V tau_d, and above 1/tau_d it
    integrates (|G| = V / w at 10 Hz within 1 %)."""
    pll = build_pll_drive(device, 25.0)
    G = phase_plant(pll)
    V = pll_steady_state(pll).v_x_amplitude_V
    tau = pll.dg.resonator.ringdown_time_constant_s("drive")
    assert float(np.real(control.dcgain(G))) == pytest.approx(-V * tau, rel=0.01)
    w = 2 * np.pi * 10.0
    assert abs(control.frequency_response(G, [w]).complex.ravel()[0]) == pytest.approx(V / w, rel=0.01)


def test_design_meets_its_targets_at_the_reference_point(device):
    d = design_pll_gains(device, 40.0, 55.0, temperatures_C=(25.0,), q_factors=(1.0,))
    m = margins(loop_transfer(build_pll_drive(device, 25.0), d.kp, d.ki_per_s))
    assert m["crossover_Hz"] == pytest.approx(40.0, rel=0.01)
    assert m["phase_margin_deg"] == pytest.approx(55.0, abs=0.5)
    assert d.rows[0]["crossover_Hz"] == pytest.approx(40.0, rel=0.01)


def test_the_envelope_engine_recovers_as_the_linear_loop_predicts(device):
    c = check_pll_gains(device, 0.7, 80.0, 85.0, frequency_error_Hz=1.0, duration_s=0.2)
    assert c["max_difference_rel"] < 0.01
    assert c["settling_simulated_s"] == pytest.approx(c["settling_linear_s"], abs=1e-3)
    assert c["simulated_Hz"][0] > 0.9 and abs(c["simulated_Hz"][-1]) < 0.02


def test_cli_tunes_the_pll(tmp_path, capsys):
    out = tmp_path / "t"
    assert main(["tune", "--loop", "pll", "--no-sim", "--json", "--q-tolerance", "0", "-o", str(out),
                 "--no-progress"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["loop"] == "pll" and data["kp"] > 0 and data["ki_per_s"] > 0
    assert data["worst"]["phase_margin_deg_min"] > 55.0
    assert (out / "tune_pll.json").is_file()


@pytest.mark.parametrize("argv,key", [(["--bandwidth-Hz", "0"], "--bandwidth-Hz"),
                                      (["--phase-margin-deg", "95"], "--phase-margin-deg")])
def test_cli_refuses_bad_targets(tmp_path, capsys, argv, key):
    assert main(["tune", "--loop", "pll", "--no-sim", "-o", str(tmp_path / "t")] + argv) == 2
    assert key in capsys.readouterr().err
