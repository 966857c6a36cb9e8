"""Closed-loop sense: force-to-rebalance and quadrature control, in the averaged model and both engines."""

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

FTR = {"circuit": {"sense": {"topology": "force-rebalance"}, "quadrature_control": {"enabled": True}}}
QC = {"circuit": {"quadrature_control": {"enabled": True}}}
STEP_DPS = 50.0
#: Rate step at this time (s) of each cross-check run; the outputs are compared after the loops settle.
T_STEP = 0.1


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


#: Simulated seconds after the step: the open sense mode rings at the split for 1/sigma = 0.1 s.
HOLD_S = {"force-rebalance": 0.25, "open-loop": 0.6}


def _cross_check_body(topology: str) -> str:
    qc = "[device.circuit.quadrature_control]\nenabled = true\n"
    sense = f'[device.circuit.sense]\ntopology = "{topology}"\n'
    rate = (f"[rate]\nstart_dps = 0.0\nsegments = [ {{ hold_s = {T_STEP} }}, {{ step_to_dps = {STEP_DPS} }}, "
            f"{{ hold_s = {HOLD_S[topology]} }} ]\n")
    return rate + sense + qc


def _metrics(res, hold_s):
    t = res.channels["time_s"]
    r = res.channels["rate_V"]
    pre = (t > T_STEP - 0.03) & (t <= T_STEP)
    post = t > T_STEP + hold_s - 0.05
    bias, final = r[pre].mean(), r[post].mean()
    sf = (final - bias) / STEP_DPS
    dev = np.abs(r - final) > 0.02 * abs(final - bias)
    late = np.flatnonzero(dev & (t > T_STEP))
    settle = (t[late[-1]] - T_STEP) if len(late) else 0.0
    return dict(bias=bias, sf=sf, settle=settle, quad=res.channels["quadrature_V"][post].mean())


@pytest.mark.parametrize("topology", ["force-rebalance", "open-loop"])
@pytest.mark.parametrize("temperature_C", [-40.0, 25.0, 85.0])
def test_envelope_matches_carrier(make_scenario, topology, temperature_C):
    """Scale factor, bias, quadrature effort and 2 % settling time of a rate step, in both engines, with the
    quadrature loop closed and the rate loop closed or open."""
    hold = HOLD_S[topology]
    path = make_scenario(_cross_check_body(topology), duration_s=T_STEP + hold, output_rate_Hz=2000.0,
                         temperature_C=temperature_C)
    car = _metrics(run_carrier(load_scenario(path, fidelity="carrier"), progress=False), hold)
    env = _metrics(run_envelope(load_scenario(path, fidelity="envelope",
                                              overrides=["scenario.envelope_step_s=0.0005"]), progress=False), hold)
    pred = steady_state(build_diagram(load_scenario(path).device, temperature_C))
    assert env["sf"] == pytest.approx(car["sf"], rel=2e-3)
    assert env["quad"] == pytest.approx(car["quad"], rel=2e-3)
    assert env["bias"] == pytest.approx(car["bias"], abs=2e-3 * abs(car["sf"]) * STEP_DPS)
    assert env["bias"] == pytest.approx(pred.rate_V, abs=2e-3 * abs(car["sf"]) * STEP_DPS)
    assert env["settle"] == pytest.approx(car["settle"], abs=0.01, rel=0.2)
