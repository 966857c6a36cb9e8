"""Closed-loop sense: force-to-rebalance and quadrature control, in the averaged model and both engines."""

import json

import numpy as np
import pytest

from blocks import RebalanceController
from fmvmg_sim.averaged import scale_factor_V_per_dps, steady_state
from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.device import load_device
from fmvmg_sim.diagram import build_diagram
from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.errors import InputError
from fmvmg_sim.rebalance import design_gains
from fmvmg_sim.scenario import load_scenario
from tests.conftest import REPO
from fmvmg_sim.tuning.rebalance import STEP_DPS, check_rate_step, robust_table, step_metrics, step_scenario

FTR = {"circuit": {"sense": {"topology": "force-rebalance"}, "quadrature_control": {"enabled": True}}}
QC = {"circuit": {"quadrature_control": {"enabled": True}}}
#: The open sense mode rings at the split for 1/sigma = 0.1 s: its runs hold the step longer.
HOLD_S = {"force-rebalance": 0.25, "open-loop": 0.6}


def _device(overrides):
    return load_device("fmvmg_a").with_overrides(overrides, "test") if overrides else load_device("fmvmg_a")


def test_scale_factor_set_by_feedback_not_split():
    """The force-to-rebalance scale factor is 2 m_c w A G_out / (K_fb k_m Vdac) and ignores the mode split."""
    dev = _device(FTR)
    dg = build_diagram(dev, 25.0)
    ss = steady_state(dg)
    loop = dg.sense_loop
    closed_form = (2 * dg.resonator.m_coriolis_kg * ss.omega_rad_s * ss.amplitude_m * dg.output_lpf.gain
                   / (loop.comb.linear_coef_N_per_V * loop.remodulator.k_per_V * dg.vdac_V) * np.pi / 180)
    sf = scale_factor_V_per_dps(dg)
    assert sf == pytest.approx(closed_form, rel=2e-3)
    wider = {"thermal": {"split_extra_Hz_per_K": 1.0}}  # the split 20 Hz wider at 45 C, the rest as at 25 C
    for extra, topo in ((FTR, "ftr"), (None, "open")):
        ov = dict(extra or {}, **wider)
        d = _device(ov)
        at25, at45 = scale_factor_V_per_dps(build_diagram(d, 25.0)), scale_factor_V_per_dps(build_diagram(d, 45.0))
        change = abs(at45 / at25 - 1)
        # between 25 and 45 C the TCF moves both by 30 ppm/K; the wider split moves the open loop by 14 %
        assert change < 0.01 if topo == "ftr" else change > 0.1, (topo, change)


def test_quadrature_control_nulls_quadrature():
    """With the tuning loop the quadrature stiffness is cancelled: its effort is k_quad / k_t (to the damping coupling's share) and the
    in-phase leak of quadrature through the sense phase (the open chain's bias) goes."""
    dg = build_diagram(_device(QC), 25.0)
    ss = steady_state(dg)
    v_t = ss.quadrature_V / dg.output_lpf.gain
    assert v_t * dg.sense_loop.electrodes.dk_dV_N_per_m_per_V == pytest.approx(abs(dg.resonator.k_quad_N_per_m),
                                                                              rel=1e-4)
    open_bias = steady_state(build_diagram(_device(None), 25.0)).rate_V
    assert abs(ss.rate_V) < 0.5 * abs(open_bias) + 1e-12 or abs(ss.rate_V) < 1e-3


def test_device_gains_are_the_design():
    """The shipped rate-loop gains are :func:`design_gains` at 25 C (the [D] source in the device file)."""
    dev = _device(FTR)
    g = design_gains(build_diagram(dev, 25.0))
    fb = dev.values["circuit"]["rebalance"]
    for key in ("kp", "ki_per_s", "kd_s"):
        assert fb[key] == pytest.approx(g[key], rel=2e-3), key


def test_controller_block_holds_its_output():
    blk = RebalanceController(kp=2.0, ki_per_s=50.0, kd_s=0.01)
    A, B, C, D = (np.asarray(m) for m in blk.abcd())
    x = blk.state_for_output(1.5)
    assert np.allclose(A @ x, 0.0) and (C @ x).item() == pytest.approx(1.5)
    assert np.asarray(blk.linear_model().D).item() == 0.0  # strictly proper: no 2-omega ripple passes directly


@pytest.mark.parametrize("body, key", [
    ('[device.circuit.sense]\ntopology = "closed"\n', "circuit.sense.topology"),
    ("[device.circuit.rebalance]\nkp = -1.0\n", "circuit.rebalance.kp"),
    ("[device.circuit.quadrature_control]\nki_per_s = 0.0\n", "circuit.quadrature_control.ki_per_s"),
])
def test_bad_input_names_the_key(make_scenario, body, key):
    with pytest.raises(InputError) as err:
        load_scenario(make_scenario(body))
    assert key in str(err.value)


@pytest.mark.parametrize("topology", ["force-rebalance", "open-loop"])
@pytest.mark.parametrize("temperature_C", [-40.0, 25.0, 85.0])
def test_envelope_matches_carrier(topology, temperature_C):
    """Scale factor, bias, quadrature effort and 2 % settling time of a rate step, in both engines, with the
    quadrature loop closed and the rate loop closed or open."""
    dev = _device({"circuit": {"sense": {"topology": topology}, "quadrature_control": {"enabled": True}}})
    hold = HOLD_S[topology]
    car = step_metrics(run_carrier(step_scenario(dev, temperature_C, hold), progress=False), hold)
    env = step_metrics(run_envelope(step_scenario(dev, temperature_C, hold, "envelope"), progress=False), hold)
    pred = steady_state(build_diagram(dev, temperature_C))
    assert env["sf"] == pytest.approx(car["sf"], rel=2e-3)
    assert env["quad"] == pytest.approx(car["quad"], rel=2e-3)
    assert env["bias"] == pytest.approx(car["bias"], abs=2e-3 * abs(car["sf"]) * STEP_DPS)
    assert env["bias"] == pytest.approx(pred.rate_V, abs=2e-3 * abs(car["sf"]) * STEP_DPS)
    assert env["settle"] == pytest.approx(car["settle"], abs=0.01, rel=0.2)


def test_tuning_margins_and_simulation_check():
    """The shipped gains keep 50 degrees of phase margin and 10 dB of gain margin over -40..85 C and Q_s +-20 %,
    and the linear model's settling time is the carrier engine's within 10 %."""
    dev = _device(FTR)
    table = robust_table(dev, [-40.0, 25.0, 85.0], (0.8, 1.2))
    assert all(m.stable for m in table)
    assert min(m.phase_margin_deg for m in table) > 50.0
    assert min(m.gain_margin_dB for m in table) > 10.0
    chk = check_rate_step(dev, 25.0)
    assert chk.settling_s == pytest.approx(chk.settling_predicted_s, rel=0.1)
    assert chk.scale_factor_V_per_dps == pytest.approx(chk.scale_factor_predicted, rel=5e-4)
    assert chk.bias_V == pytest.approx(chk.bias_predicted_V, abs=1e-3)


def test_rate_loop_without_quadrature_loop():
    """Without the quadrature loop the demodulator's 2-omega ripple of the quadrature signal reaches the
    derivative; the fourth-order filter keeps what it adds to the bias in the carrier engine (which the
    averaged model leaves out) below 0.15 deg/s, the scale factor within 1e-3."""
    dev = _device({"circuit": {"sense": {"topology": "force-rebalance"}}})
    car = step_metrics(run_carrier(step_scenario(dev, 25.0, 0.25), progress=False), 0.25)
    dg = build_diagram(dev, 25.0)
    sf = scale_factor_V_per_dps(dg)
    assert car["sf"] == pytest.approx(sf, rel=1e-3)
    assert abs(car["bias"] - steady_state(dg).rate_V) / sf < 0.15


def test_tune_rebalance_cli(tmp_path, capsys):
    """``fmvmg tune --loop rebalance`` designs gains for a bandwidth and reports the margins; bad input exits 2."""
    from fmvmg_sim.cli.main import main
    out = tmp_path / "tune"
    assert main(["tune", str(REPO / "scenarios" / "force_rebalance_rate.toml"), "--loop", "rebalance", "--bandwidth-Hz", "30",
                 "--no-sim", "--grid-points", "2", "--q-tolerance", "0", "-o", str(out), "--json",
                 "--no-progress"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["gains"]["ki_per_s"] == pytest.approx(2553.0 * 30 / 50, rel=0.01)  # Ki scales with the pole
    assert data["worst"]["stable"] and data["worst"]["phase_margin_deg"] > 45
    assert (out / "tune.json").exists()
    assert main(["tune", "--loop", "rebalance", "--bandwidth-Hz", "0", "-o", str(tmp_path / "x")]) == 2
    assert "--bandwidth-Hz" in capsys.readouterr().err
