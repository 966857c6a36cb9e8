"""The PLL drive: its locked steady state, lock acquisition and tracking, and its envelope against its carrier."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from fmvmg_sim.averaged import scale_factor_V_per_dps, steady_state
from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.cli.main import main
from fmvmg_sim.device import load_device
from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.errors import InputError
from fmvmg_sim.pll_drive import build_pll_drive, pll_scale_factor_V_per_dps, pll_steady_state
from fmvmg_sim.scenario import load_scenario

PLL = '\n[circuit.drive]\ntopology = "pll"\n'
RATE_STEPS = PLL + """
[rate]
start_dps = 0.0
segments = [ { hold_s = 0.4 }, { step_to_dps = 20.0 }, { hold_s = 0.4 }, { step_to_dps = -20.0 } ]
"""


def _pll_device(**pll):
    return load_device("fmvmg_a").with_overrides({"circuit": {"drive": {"topology": "pll"}, "pll": pll}}, "test")


def _mean(res, name, a, b):
    t = res.time_s
    return float(np.mean(res[name][(t > a) & (t < b)]))


def _both(path, overrides=()):
    c = run_carrier(load_scenario(path, list(overrides), fidelity="carrier"), progress=False)
    e = run_envelope(load_scenario(path, list(overrides), fidelity="envelope"), progress=False)
    return c, e


def lock_time_s(res, tol_Hz=0.1):
    """First time after which the oscillator stays within ``tol_Hz`` of its final frequency."""
    f = res["drive_frequency_Hz"]
    off = np.abs(f - np.mean(f[-20:])) > tol_Hz
    return float(res.time_s[np.flatnonzero(off)[-1] + 1]) if off.any() else 0.0


# --- the locked steady state -----------------------------------------------------------------------------
def test_lock_point_is_the_resonance_at_the_trim_temperature():
    """At the reference temperature the trimmed phase detector locks on the drive resonance (within 1 % of its
    half-bandwidth), the tuning voltage holds the offset from the free-running frequency, and the amplitude and
    scale factor are the self-oscillating loop's (one Vref, one amplitude)."""
    dev = _pll_device(f_free_offset_Hz=20.0)
    pll = build_pll_drive(dev, 25.0)
    ss = pll_steady_state(pll)
    res = pll.dg.resonator
    assert abs(ss.f_Hz - res.f_drive_Hz) < 0.01 * res.f_drive_Hz / (2 * res.q_drive)
    assert ss.v_tune_V == pytest.approx((ss.f_Hz - pll.nco.f_free_Hz) / pll.nco.k_vco_Hz_per_V, rel=1e-12)
    assert ss.v_tune_V == pytest.approx(-20.0 / 50.0, rel=1e-3) and ss.locked
    so = steady_state(pll.dg)
    assert ss.amplitude_m == pytest.approx(so.amplitude_m, rel=1e-6)
    assert pll_scale_factor_V_per_dps(pll) == pytest.approx(scale_factor_V_per_dps(pll.dg), rel=1e-4)
    assert ss.rate_V == pytest.approx(so.rate_V, rel=1e-3)


def test_the_phase_shifter_drift_does_not_reach_the_pll_drive():
    """The phase shifter is not in the PLL drive: its RC drift moves the self-oscillating loop's bias at 60 C,
    not the PLL's."""
    def biases(rc_tc):
        dev = _pll_device().with_overrides({"circuit": {"phase_shifter": {"rc_tc_per_K": rc_tc}}}, "test")
        pll = build_pll_drive(dev, 60.0)
        return pll_steady_state(pll).rate_V, steady_state(pll.dg).rate_V
    (p0, s0), (p1, s1) = biases(0.0), biases(500e-6)
    assert p1 == pytest.approx(p0, rel=1e-9)
    assert abs(s1 - s0) > 10 * abs(p1 - p0) + 1e-4


# --- both engines ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("T", [-40.0, 25.0, 85.0])
def test_pll_envelope_agrees_with_carrier(make_scenario, T):
    c, e = _both(make_scenario(RATE_STEPS, duration_s=1.2, temperature_C=T))
    amp = [_mean(r, "drive_displacement_amplitude_m", 0.1, 0.4) for r in (c, e)]
    eff = [_mean(r, "agc_effort_V", 0.1, 0.4) for r in (c, e)]
    bias = [_mean(r, "rate_dps", 0.2, 0.4) for r in (c, e)]
    sf = [(_mean(r, "rate_V", 0.6, 0.8) - _mean(r, "rate_V", 1.0, 1.2)) / 40.0 for r in (c, e)]
    freq = [_mean(r, "drive_frequency_Hz", 0.1, 0.4) for r in (c, e)]
    assert amp[1] == pytest.approx(amp[0], rel=1e-5)
    assert eff[1] == pytest.approx(eff[0], rel=1e-3)  # the comb's quadratic force is not in the envelope
    assert sf[1] == pytest.approx(sf[0], rel=1e-3)
    assert bias[1] == pytest.approx(bias[0], abs=1e-3)  # deg/s
    assert freq[1] == pytest.approx(freq[0], abs=1e-3)
    # and both on the averaged steady state
    pll = build_pll_drive(load_scenario(make_scenario(PLL)).device, T)
    ss = pll_steady_state(pll)
    assert freq[0] == pytest.approx(ss.f_Hz, abs=1e-3)
    assert eff[0] == pytest.approx(ss.agc_effort_V, rel=1e-3)
    assert sf[0] == pytest.approx(pll_scale_factor_V_per_dps(pll), rel=5e-3)


@pytest.mark.parametrize("offset_Hz", [20.0, -20.0])
def test_lock_acquisition_from_start_up(make_scenario, offset_Hz):
    """From 10 nm at rest, the oscillator 20 Hz off: both engines lock within 0.12 s, within 1 ms of each
    other, on the steady state's frequency and amplitude."""
    body = PLL + f"[circuit.pll]\nf_free_offset_Hz = {offset_Hz}\n"
    path = make_scenario(body, duration_s=0.5, state="rest", output_rate_Hz=2000.0)
    c, e = _both(path)
    tc, te = lock_time_s(c), lock_time_s(e)
    assert 0.02 < tc < 0.12
    assert te == pytest.approx(tc, abs=1e-3)
    ss = pll_steady_state(build_pll_drive(load_scenario(path).device, 25.0))
    for r in (c, e):
        assert _mean(r, "drive_frequency_Hz", 0.3, 0.5) == pytest.approx(ss.f_Hz, abs=0.005)
        assert _mean(r, "agc_effort_V", 0.3, 0.5) == pytest.approx(ss.agc_effort_V, rel=2e-3)
    t = e.time_s
    win = t > 0.05
    rc = np.interp(t, c.time_s, c["drive_amplitude_V"])
    assert np.max(np.abs(e["drive_amplitude_V"][win] - rc[win])) < 2e-3 * ss.v_x_amplitude_V


def test_pll_tracks_the_resonance_over_a_ramp(make_scenario):
    """Over a 60 C/min ramp the drive resonance moves 0.9 Hz/s; the oscillator stays close to its
    steady lock point at each sample's temperature (within 4 mHz), and settles on it after the ramp."""
    temp = "start_C = 25.0\nsegments = [ { hold_s = 1.0 }, { ramp_to_C = 35.0, rate_C_per_min = 60.0 }, { hold_s = 4.0 } ]"
    path = make_scenario(PLL, duration_s=15.0, fidelity="envelope", output_rate_Hz=100.0)
    path.write_text(path.read_text().replace("start_C = 25.0", temp))
    scn = load_scenario(path)
    r = run_envelope(scn, progress=False)
    dev = scn.device
    T_mid = np.asarray(scn.temperature(r.time_s - 0.005))  # the frequency channel is a mean over the sample
    grid = np.linspace(24.0, 36.0, 25)
    lock = CubicSpline(grid, [pll_steady_state(build_pll_drive(dev, T)).f_Hz for T in grid])(T_mid)
    f_res = np.array([dev.at(T)["mechanics"]["f_drive_Hz"] for T in (25.0, 35.0)])
    assert abs(f_res[1] - f_res[0]) > 8.0
    err = r["drive_frequency_Hz"] - lock
    assert np.max(np.abs(err[r.time_s > 0.05])) < 4e-3  # 2.6 mHz at the ramp's corners
    assert abs(np.mean(err[(r.time_s > 13.0)])) < 1e-5


# --- bad input -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("over,key", [({"drive": {"topology": "phase-locked"}}, "circuit.drive.topology"),
                                      ({"pll": {"k_vco_Hz_per_V": 0.0}}, "circuit.pll.k_vco_Hz_per_V"),
                                      ({"pll": {"k_vco_Hz_per_V": -5.0}}, "circuit.pll.k_vco_Hz_per_V"),
                                      ({"pll": {"v_min_V": 5.0, "v_max_V": 1.0}}, "circuit.pll.v_min_V")])
def test_bad_pll_settings_name_the_key(over, key):
    with pytest.raises(InputError, match=key.replace(".", r"\.")):
        load_device("fmvmg_a").with_overrides({"circuit": over}, "x.toml")


def test_bad_topology_exits_2_from_the_cli(make_scenario, tmp_path, capsys):
    path = make_scenario('\n[circuit.drive]\ntopology = "vco"\n')
    assert main(["run", str(path), "-o", str(tmp_path / "o")]) == 2
    assert "circuit.drive.topology" in capsys.readouterr().err


def test_pll_bias_tc_board_share_is_the_loops_without_the_phase_shifter():
    """Through the board, the PLL's bias moves as the self-oscillating loop's does with the RC drift removed: what
    the phase shifter's drift adds (on fmvmg_a it cancels part of the amplifiers') is all the difference."""
    from fmvmg_sim.diagram import build_diagram
    dev = load_device("fmvmg_a")
    flat = dev.with_overrides({"circuit": {"phase_shifter": {"rc_tc_per_K": 0.0}}}, "test")
    pll_dev = dev.with_overrides({"circuit": {"drive": {"topology": "pll"}}}, "test")

    def share(bias, sf):
        return 3600 * (bias(26.0) - bias(24.0)) / 2 / sf

    pll_share = share(lambda b: pll_steady_state(build_pll_drive(pll_dev, 25.0, b)).rate_V,
                      pll_scale_factor_V_per_dps(build_pll_drive(pll_dev, 25.0)))
    flat_share = share(lambda b: steady_state(build_diagram(flat, 25.0, board_C=b)).rate_V,
                       scale_factor_V_per_dps(build_diagram(flat, 25.0)))
    loop_share = share(lambda b: steady_state(build_diagram(dev, 25.0, board_C=b)).rate_V,
                       scale_factor_V_per_dps(build_diagram(dev, 25.0)))
    assert pll_share == pytest.approx(flat_share, rel=0.02)
    assert abs(pll_share - loop_share) > 10.0  # deg/h per K
