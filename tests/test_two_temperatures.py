"""The MEMS on the die temperature, the electronics on the board (case) temperature.

Without a thermal lag the two are one temperature and records are what a single temperature gives;
with a lag the engines agree with each other and with the averaged model at (die, board), and the
bias departs from the die's law by the closed form of the electronic phase drift.
"""

from collections import OrderedDict

import numpy as np
import pytest

from fmvmg_sim.averaged import bias_temperature_coefficients_dph_per_K, steady_state
from fmvmg_sim.carrier import engine as carrier_engine
from fmvmg_sim.carrier import kits as carrier_kits
from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.device import BOARD_LAWS, load_device
from fmvmg_sim.diagram import build_diagram
from fmvmg_sim.effects import EffectSet
from fmvmg_sim.envelope import engine as envelope_engine
from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.scenario import load_scenario

from .closed_forms import zero_rate_output_dps
from .conftest import REPO

DEVICES = ("fmvmg_a", "fmvmg_b", "dualmass_004")
#: Effects that give every board law a non-zero coefficient (the shipped devices leave some at zero).
BOARD_EFFECTS = {"feedthrough": {"c_ft_fF": 5.0, "tc_per_K": 3e-4},
                 "reference_drift": {"vref_tc_per_K": 5e-5, "rectifier_mV_per_K": -2.0},
                 "demod_phase_drift": {"kappa_urad_per_K": 100.0}}
RECORD_CHANNELS = ("rate_V", "quadrature_V", "drive_amplitude_V", "agc_effort_V", "drive_frequency_Hz")


def _leaves(tree, prefix=""):
    out = {}
    for k, v in tree.items():
        if isinstance(v, dict):
            out.update(_leaves(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out


@pytest.mark.parametrize("name", DEVICES)
def test_mems_laws_follow_the_die_and_electronics_laws_the_board(name):
    dev = EffectSet(BOARD_EFFECTS).apply_to_device(load_device(name))
    leaves = _leaves(dev.values)
    assert all(leaves[k] != 0.0 for k in BOARD_LAWS)  # every board law is switched on here
    T0 = dev.reference_temperature_C
    ref = dev.at(T0)
    hot_die, hot_board = dev.at(T0 + 20.0, board_C=T0), dev.at(T0, board_C=T0 + 20.0)
    assert _leaves(hot_die["circuit"]) == _leaves(ref["circuit"])
    assert hot_die["demod_phase_drift_rad"] == ref["demod_phase_drift_rad"] == 0.0
    assert _leaves(hot_board["mechanics"]) == _leaves(ref["mechanics"])
    assert {k for k, v in _leaves(hot_die["mechanics"]).items() if v != _leaves(ref["mechanics"])[k]} == {
        "f_drive_Hz", "f_sense_Hz", "q_drive", "q_sense", "k_quad_N_per_m", "c_quad_N_s_per_m", "temperature_K"}
    # each law on the board moves exactly the block value it sets
    moved = {k for k, v in _leaves(hot_board["circuit"]).items() if v != _leaves(ref["circuit"])[k]}
    assert moved == {f"{a}.{p}" for a in ("drive_amp", "sense_amp1", "sense_amp2") for p in ("gain", "gbw_Hz")} | {
        "phase_shifter.delta_T_K", "rectifier.offset_V", "reference.vref_V", "sense_pickoff.c_feedthrough_F"}
    assert hot_board["demod_phase_drift_rad"] == pytest.approx(100e-6 * 20.0)
    # one temperature for both is the default, value for value
    for T in (-40.0, T0, 61.3):
        assert dev.at(T).values == dev.at(T, board_C=T).values


@pytest.mark.parametrize("name", DEVICES)
def test_bias_tc_splits_into_die_and_board_shares(name):
    """The averaged model's bias TC with die and board together is the sum of the two shares."""
    tc = bias_temperature_coefficients_dph_per_K(load_device(name))
    assert tc["total"] == pytest.approx(tc["die"] + tc["board"], abs=0.01 * abs(tc["total"]))


def _without_board(build):
    """``build_diagram`` as it was before the board temperature existed: one temperature for everything."""
    return lambda device, T, quad_delta_rel=0.0, board_C=None: build(device, T, quad_delta_rel)


def test_records_without_thermal_lag_are_unchanged(monkeypatch):
    """On the shipped oven scenario (noise on), each engine's record is bit for bit the one-temperature record."""
    runs = {}
    for tag in ("board", "one"):
        with monkeypatch.context() as m:
            if tag == "one":
                m.setattr(carrier_kits, "build_diagram", _without_board(carrier_kits.build_diagram))
                m.setattr(envelope_engine, "build_diagram", _without_board(envelope_engine.build_diagram))
            m.setattr(carrier_engine, "_PLANS", OrderedDict())  # no operating point from the other run
            path = REPO / "scenarios" / "oven_000.toml"
            env = run_envelope(load_scenario(path, overrides=["scenario.duration_s=2400", "scenario.output_rate_Hz=10"]),
                               progress=False)
            car = run_carrier(load_scenario(path, fidelity="carrier", overrides=[
                "scenario.duration_s=0.2", "scenario.output_rate_Hz=100",
                "temperature.segments=[{ramp_to_C=26.0,rate_C_per_min=300.0}]"]), progress=False)
            runs[tag] = (env, car)
    assert runs["board"][1].info["operating_points"] >= 10  # the carrier run visits many temperatures
    for new, old in zip(runs["board"], runs["one"]):
        for c in RECORD_CHANNELS:
            np.testing.assert_array_equal(new[c], old[c], err_msg=c)


LAG_STEP = """
[effects]
thermal_lag = { tau_s = 600.0, offset_K = 0.5 }
"""


def _mean(res, name, a, b):
    t = res.time_s
    return float(np.nanmean(res[name][(t > a) & (t < b)]))


def test_engines_agree_under_thermal_lag(make_scenario):
    """The case steps 3 K in 0.3 s: the board follows, the die (600 s behind) barely moves.

    Both engines' changes of bias, drive frequency and amplitude across the step are the averaged
    model's at (die, board); had the electronics followed the die, the bias would have moved by
    the die's 0.01 K only.
    """
    seg = ["temperature.segments=[{hold_s=1.0},{ramp_to_C=28.0,rate_C_per_min=600.0}]"]
    path = make_scenario(LAG_STEP, duration_s=3.0, output_rate_Hz=100.0)
    runs = {fid: (run_carrier if fid == "carrier" else run_envelope)(
        load_scenario(path, fidelity=fid, overrides=seg), progress=False) for fid in ("carrier", "envelope")}
    scn = load_scenario(path, overrides=seg)
    c = runs["carrier"]
    die, board = c.internal["die_temperature_C"], c["temperature_C"]
    t = c.time_s
    before, after = (0.3, 1.0), (2.0, 3.0)
    d0, b0 = _mean(c, "temperature_C", *before) + 0.5, 25.0
    d1 = float(np.mean(die[(t > after[0]) & (t < after[1])]))
    assert np.mean(board[(t > after[0]) & (t < after[1])]) == pytest.approx(28.0)
    assert 0.0 < d1 - d0 < 0.02  # the die has hardly moved
    sf = c.info["nominal_scale_factor_V_per_dps"]

    def avg(die_C, board_C):
        ss = steady_state(build_diagram(scn.device, die_C, board_C=board_C))
        return dict(rate_dps=ss.rate_V / sf, drive_frequency_Hz=ss.f_Hz,
                    drive_displacement_amplitude_m=ss.amplitude_m, agc_effort_V=ss.agc_effort_V)

    p0, p1, p_die = avg(d0, b0), avg(d1, 28.0), avg(d1, d1)
    board_share = p1["rate_dps"] - p_die["rate_dps"]
    assert abs(board_share) > 0.02  # deg/s: the board's 3 K are resolved (about -31 deg/h per K)
    for fid, r in runs.items():
        def change(name):
            if name == "drive_displacement_amplitude_m":
                get = lambda a, b: float(np.mean(r.internal[name][(r.time_s > a) & (r.time_s < b)]))  # noqa: E731
            else:
                get = lambda a, b: _mean(r, name, a, b)  # noqa: E731
            return get(*after) - get(*before), get(*after)
        d_bias, bias1 = change("rate_dps")
        assert d_bias == pytest.approx(p1["rate_dps"] - p0["rate_dps"], abs=0.03 * abs(board_share)), fid
        d_f, f1 = change("drive_frequency_Hz")
        assert d_f == pytest.approx(p1["drive_frequency_Hz"] - p0["drive_frequency_Hz"], abs=2e-3), fid
        assert f1 == pytest.approx(p1["drive_frequency_Hz"], abs=0.01), fid
        _, a1 = change("drive_displacement_amplitude_m")
        assert a1 == pytest.approx(p1["drive_displacement_amplitude_m"], rel=1e-3), fid
        _, u1 = change("agc_effort_V")
        assert u1 == pytest.approx(p1["agc_effort_V"], rel=5e-3), fid
    e = runs["envelope"]
    assert _mean(e, "rate_dps", *after) == pytest.approx(_mean(c, "rate_dps", *after), abs=0.03 * abs(board_share))


CYCLE = ["temperature.segments=[{hold_s=60.0},{ramp_to_C=45.0,rate_C_per_min=1.0},{hold_s=1200.0},"
         "{ramp_to_C=25.0,rate_C_per_min=1.0},{hold_s=600.0}]"]


def test_bias_departs_from_the_die_law_by_the_closed_form_electronic_phase(make_scenario):
    """A 25 -> 45 -> 25 C cycle at 1 K/min with the die 600 s behind the case (envelope engine, noise off).

    The drive frequency reads the die: it is what the same cycle without lag gives at that die
    temperature. The bias is not: it departs from the no-lag bias at the same die temperature by
    the closed form's ``Omega_c cos(phi) - Omega_q sin(phi)`` with the electronic phase at the board instead of
    the die (about ``-Omega_q [phi_el(T_board) - phi_el(T_die)]``), so bias against drive frequency is a loop,
    open by the board term, where a single temperature would give one curve.
    """
    lag_body = LAG_STEP.replace("offset_K = 0.5", "offset_K = 0.0")
    lagged, plain = (run_envelope(load_scenario(make_scenario(body, name=name, duration_s=4260.0, output_rate_Hz=2.0,
                                                              fidelity="envelope"), overrides=CYCLE), progress=False)
                     for name, body in (("lag", lag_body), ("plain", "")))
    dev = load_device("fmvmg_a")

    def means(res, x):  # 10 s means: the envelope's parameters step once a second
        return np.asarray(x)[:len(res.time_s) // 20 * 20].reshape(-1, 20).mean(axis=1)

    t, die, board, f, bias = (means(lagged, x) for x in (lagged.time_s, lagged.internal["die_temperature_C"],
                                                          lagged["temperature_C"], lagged["drive_frequency_Hz"],
                                                          lagged["rate_dps"]))
    assert np.max(board - die) > 8.0 and np.min(board - die) < -8.0  # 10 K lag on the ramps
    # the no-lag cycle's heating ramp: bias and drive frequency as functions of the one temperature
    tp, Tp, fp, bp = (means(plain, x) for x in (plain.time_s, plain["temperature_C"], plain["drive_frequency_Hz"],
                                                plain["rate_dps"]))
    up = (tp > 90.0) & (tp < 1250.0)
    sel = (t > 90.0) & (die > Tp[up][0]) & (die < Tp[up][-1])
    t, die, board, f, bias = (x[sel] for x in (t, die, board, f, bias))
    # the drive frequency reads the die to 10 mK (-0.92 Hz/K) while the board is up to 10 K away; what is left
    # is the drive mode's response time 2 Q_d / w_d = 0.2 s to the ramping frequency (4 mHz at 1 K/min)
    assert np.max(np.abs(f - np.interp(die, Tp[up], fp[up]))) < 0.01
    # closed form of the bias's board term: the MEMS at the die, the electronics at the board or at the die
    closed = np.array([zero_rate_output_dps(dev, d, b) - zero_rate_output_dps(dev, d, d) for d, b in zip(die, board)])
    measured = bias - np.interp(die, Tp[up], bp[up])
    peak = np.max(np.abs(closed))
    assert peak * 3600 > 200.0  # deg/h: the board term is large on these ramps (the check is not vacuous)
    assert np.max(np.abs(measured - closed)) < 0.03 * peak
    # bias against drive frequency: heating and cooling pass the same drive frequency (die at 35 C) with
    # the board on either side of it, and the bias differs by the board term there, not by zero
    k_up = np.argmin(np.abs(die - 35.0) + 1e3 * (t > 1500.0))
    k_dn = np.argmin(np.abs(die - 35.0) + 1e3 * (t < 2500.0))
    assert f[k_up] == pytest.approx(f[k_dn], abs=0.2)
    opening = bias[k_up] - bias[k_dn]
    assert opening == pytest.approx(closed[k_up] - closed[k_dn], rel=0.05)
    assert abs(opening) > 0.5 * peak


def test_summary_prediction_puts_the_die_at_the_lag_offset(make_scenario):
    """After a long hold the die sits at the case plus the lag's offset, the board at the case."""
    from fmvmg_sim.runner import predictions
    scn = load_scenario(make_scenario(LAG_STEP, fidelity="envelope"))
    p = predictions(scn, 40.0)
    ss = steady_state(build_diagram(scn.device, 40.5, board_C=40.0))
    assert (p["drive_frequency_Hz"], p["agc_effort_V"]) == (ss.f_Hz, ss.agc_effort_V)
    assert abs(p["drive_frequency_Hz"] - steady_state(build_diagram(scn.device, 40.0)).f_Hz) > 0.4  # 0.5 K of die
