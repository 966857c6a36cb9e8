"""The diagnosis benchmark's case generator: units drawn across the nominal model's stated uncertainty, effects
scaled to a signature SNR in the record's own noise, out-of-library disturbances, the case mix."""

import numpy as np
import pytest

from fmvmg_sim.diagnosis.evaluation import bound_check
from fmvmg_sim.diagnosis.parameters import KnobSet
from fmvmg_sim.effects import MODELS
from fmvmg_sim.record import read_record
from fmvmg_sim.scenario import load_scenario
from fmvmg_sim.uncertainty import apply_channels
from fmvmg_sim.validation.cases import (OUT_OF_LIBRARY, P_NULL, P_SINGLE, SNR_TARGET, CaseMix, MixError, _scale_to,
                                        add_out_of_library, make_case, noise_model, out_of_library_shape, recorded,
                                        scaled, separable_snr, signature_snr, snr_beyond, tier, training_snr,
                                        unit_device)
from tests.test_diagnosis_helpers import A_UNIT as THETA
from tests.test_diagnosis_helpers import LATE_RAMP, NOMINAL, oven_record

pytestmark = pytest.mark.xdist_group("case_generator")


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    """A unit off nominal (values, laws and channels) on the short oven, with its noise model."""
    tmp = tmp_path_factory.mktemp("twin")
    rec, _ = oven_record(tmp, "twin", seed=21, theta=THETA)
    dev = load_scenario(NOMINAL).device_nominal
    return rec, dev, noise_model(read_record(rec), dev, THETA)


def test_signature_snr_counts_the_records_slow_noise(twin):
    # the detection limit is in units of the record's noise: a white model reproduces the white-noise
    # SNR exactly, and the rate output's flicker wander (the noise model of a noise-only twin) lowers the
    # SNR of a slow rate-channel signature (a temperature-rate term follows the oven, not the noise)
    rec, dev, noise = twin
    eff = {"temperature_rate": {"g_dph_per_K_per_min": 60.0}}
    white = signature_snr(rec, NOMINAL, dev, THETA, eff)
    assert white > 10
    assert abs(signature_snr(rec, NOMINAL, dev, THETA, eff, noise=[(0.0, 1.0, 1.0)] * 5) / white - 1) < 1e-9
    rho, K, s = noise[0]                                    # rate channel: a slow state under white noise
    assert rho > 0.8 and K < 0.6
    coloured = signature_snr(rec, NOMINAL, dev, THETA, eff, noise=noise)
    assert coloured < 0.5 * white
    # a drive-frequency signature (Duffing), where the block sigma is a model floor: never credited
    # beyond its white-noise SNR
    duff = {"duffing": {"k3_rel": 3e-6}}
    assert signature_snr(rec, NOMINAL, dev, THETA, duff, noise=noise) <= signature_snr(rec, NOMINAL, dev, THETA, duff)
    # aiming a Duffing term at an SNR its oscillation cannot reach backs off instead of failing the case
    scale, snr = _scale_to(rec, NOMINAL, dev, THETA, {"duffing": {"k3_rel": 3e-4}}, 800.0, noise=noise)
    assert scale > 1.0 and 0 < snr < 800.0


def test_separable_snr_is_what_the_partner_cannot_explain(twin):
    # a Q drift inside the Q law's tolerance is the nominal model's uncertainty: the calibration absorbs it; one
    # beyond it is not. A reference drift (u ~ A/Q through the AGC effort) explains part of the Q drift beyond the
    # law's bound, an unrelated temperature-rate term none of it; a temperature-rate term follows the oven's ramps,
    # which a quadrature drift (a law in temperature) cannot mimic, so beside it it keeps its own SNR; beside a noise
    # level nothing is absorbed
    rec, dev, noise = twin
    assert signature_snr(rec, NOMINAL, dev, THETA, {"q_factor_drift": {"q_tc_per_K": 3e-5}}, noise=noise) < 5.0
    q = {"q_factor_drift": {"q_tc_per_K": 1e-2}}
    own_q = signature_snr(rec, NOMINAL, dev, THETA, q, noise=noise)
    assert own_q > 50.0
    assert abs(snr_beyond(rec, dev, THETA, q, noise, []) / own_q - 1) < 1e-9
    assert snr_beyond(rec, dev, THETA, q, noise, ["reference_drift"]) < 0.6 * own_q
    assert snr_beyond(rec, dev, THETA, q, noise, ["temperature_rate", "quantization"]) > 0.95 * own_q
    distinct = {"temperature_rate": {"g_dph_per_K_per_min": 600.0}, "quadrature_drift": {"beta_per_K": 1e-2}}
    own = {n: signature_snr(rec, NOMINAL, dev, THETA, {n: v}, noise=noise) for n, v in distinct.items()}
    assert min(own.values()) > 40, own  # both far above the detection limit
    sep = separable_snr(rec, dev, THETA, distinct, noise, own)
    assert abs(sep["temperature_rate"] / own["temperature_rate"] - 1) < 0.05, (own, sep)
    with_noise = {"temperature_rate": {"g_dph_per_K_per_min": 600.0}, "quantization": {"lsb_V": 0.005}}
    own = {"temperature_rate": 60.0, "quantization": 32.0}
    assert separable_snr(rec, dev, THETA, with_noise, noise, own) == own
    single = {"temperature_rate": {"g_dph_per_K_per_min": 600.0}}
    assert separable_snr(rec, dev, THETA, single, noise, {"temperature_rate": 60.0}) == {"temperature_rate": 60.0}


def test_training_snr_is_what_the_training_window_carries(tmp_path):
    # a temperature-rate term acts only while the oven ramps: with the record's one ramp in its held-out end
    # (the last fold's test segment starts at 80 % of the record, its training ends at 76 %), the diagnoser's
    # training window carries none of it, however high the whole-record SNR; with the ramps early, most of it
    late = LATE_RAMP
    dev = load_scenario(NOMINAL).device_nominal
    eff = {"temperature_rate": {"g_dph_per_K_per_min": 600.0}}
    for name, profile in (("late", late), ("early", None)):
        kw = {"profile": profile} if profile else {}
        rec, _ = oven_record(tmp_path, name, seed=21, theta=THETA, **kw)
        noise = noise_model(read_record(rec), dev, THETA)
        whole = signature_snr(rec, NOMINAL, dev, THETA, eff, noise=noise)
        train = training_snr(rec, dev, THETA, eff, noise)
        assert whole > 30, (name, whole)
        if name == "late":
            assert train < 0.05 * whole, (whole, train)
        else:
            assert 0.5 * whole < train < 1.05 * whole, (whole, train)
    # no effect, no signature; a noise level keeps its analytic SNR (its band is read on the whole record)
    assert training_snr(rec, dev, THETA, {}, noise) == 0.0
    q = {"quantization": {"lsb_V": 0.005}}
    assert training_snr(rec, dev, THETA, q, noise) == signature_snr(rec, NOMINAL, dev, THETA, q, noise=noise) > 10


def test_scaled_cases_stay_clear_of_physical_bounds():
    # a case's amplitude scaled past its bound is clipped inside it, where the diagnosis's
    # "not pinned at a bound" rule can accept a right answer; time constants are left alone
    eff = scaled({"stress_relaxation": {"quad_rel": -0.1, "tau_h": 20.0}}, 5.0)
    assert -0.2 < eff["stress_relaxation"]["quad_rel"] <= -0.19 and eff["stress_relaxation"]["tau_h"] == 20.0
    assert bound_check(eff) == (None, [])
    assert bound_check({"stress_relaxation": {"quad_rel": -0.2, "tau_h": 20.0}}) == (None, ["stress_relaxation.quad_rel"])


def test_case_mix_checks_its_choices():
    d = CaseMix.build()
    assert d == CaseMix() and d.effects == tuple(MODELS) and (d.p_null, d.p_single) == (P_NULL, P_SINGLE)
    assert d.snr_range == SNR_TARGET
    # library order, duplicates dropped
    m = CaseMix.build(["reference_drift", "q_factor_drift", "reference_drift"], "single", 10.0, 1000.0)
    assert m.effects == ("q_factor_drift", "reference_drift") and (m.p_null, m.p_single) == (0.0, 1.0)
    assert CaseMix.build(["duffing", "feedthrough"], "pair").p_single == 0.0
    assert (CaseMix.build(kind="null").p_null, CaseMix.build(["duffing"], "null").p_single) == (1.0, 0.0)
    for args, field in [((["q_drift"],), "effects"), (([],), "effects"), ((None, "triple"), "kind"), ((["duffing"], "default"), "effects"),
                        ((None, "single", 0.0, 10.0), "snr"), ((None, "single", 10.0, 10.0), "snr"),
                        ((None, "single", 1.0, float("inf")), "snr")]:
        with pytest.raises(MixError) as e:
            CaseMix.build(*args)
        assert e.value.field == field, (args, e.value.field)
    assert "q_factor_drift" in str(pytest.raises(MixError, CaseMix.build, ["q_drift"]).value)   # lists the known ones


def test_a_narrow_mix_draws_single_effects_from_its_pool(tmp_path):
    mix = CaseMix.build(["q_factor_drift", "reference_drift"], "single", 10.0, 1000.0)
    for k in range(2):
        lab = make_case(k, 60221, tmp_path, str(NOMINAL), duration_s=1.1 * 3600.0, mix=mix)
        assert len(lab["effects"]) == 1 and set(lab["effects"]) <= set(mix.effects)
        assert 10.0 <= lab["snr_target"] <= 1000.0
    assert not make_case(0, 60221, tmp_path / "n", str(NOMINAL), duration_s=1.1 * 3600.0,
                         mix=CaseMix.build(kind="null"))["effects"]
    # the default mix draws the same case as before the mix existed (no mix given)
    a = make_case(5, 4242, tmp_path / "a", str(NOMINAL), duration_s=1.1 * 3600.0)
    b = make_case(5, 4242, tmp_path / "b", str(NOMINAL), duration_s=1.1 * 3600.0, mix=CaseMix())
    assert {k: v for k, v in a.items() if k != "record"} == {k: v for k, v in b.items() if k != "record"}


def test_out_of_library_disturbances(tmp_path):
    # a unit sine in time, and a step from 0 to 1 that is half-way at its time and done within its rise
    t = np.arange(0.0, 10800.0)
    w = out_of_library_shape({"kind": "bias_wander", "period_s": 3000.0, "phase_rad": 0.0}, t)
    assert abs(w[750] - 1.0) < 1e-12 and abs(w[1500]) < 1e-12 and abs(w[2250] + 1.0) < 1e-12
    st = out_of_library_shape({"kind": "bias_step", "t_step_s": 5000.0, "rise_s": 60.0}, t)
    assert st[5000] == 0.5 and st[4850] < 1e-3 and st[5150] > 1.0 - 1e-3 and np.all(np.diff(st) >= 0)
    with pytest.raises(ValueError, match="bias_wander"):
        out_of_library_shape({"kind": "sine"}, t)
    assert OUT_OF_LIBRARY == ("bias_wander", "bias_step")


def test_out_of_library_case_reaches_its_snr_on_the_lattice(tmp_path):
    # added before the converter (the output stays on its lattice), in deg/s as drawn, at the SNR aimed at
    rec, _ = oven_record(tmp_path, "ool_case", seed=16, theta=THETA)
    before = read_record(rec)
    dev = load_scenario(NOMINAL).device_nominal
    sf = dev.nominal_scale_factor_V_per_dps
    lsb = dev.values["noise"]["quantization_lsb_V"]
    ool = {"kind": "bias_wander", "period_s": 2400.0, "phase_rad": 0.3}
    got = add_out_of_library(rec, ool, 40.0, dev, [(0.0, 1.0, 1.0)] * 5)
    after = read_record(rec)
    assert got["kind"] == "bias_wander" and abs(got["snr"] / 40.0 - 1.0) < 1e-9
    assert 0.0 < got["amplitude_dps"] < 2.0
    k = after.columns["rate_V"] / lsb
    assert np.nanmax(np.abs(k - np.round(k))) < 1e-6                    # on the converter's lattice
    added = after.columns["rate_V"] - before.columns["rate_V"]
    want = got["amplitude_dps"] * out_of_library_shape(ool, before.columns["time_s"]) * sf
    assert np.nanmax(np.abs(added - want)) <= lsb * (1 + 1e-6)           # within one converter step
    assert np.allclose(after.columns["rate_dps"] * sf, after.columns["rate_V"], rtol=1e-6, atol=1e-12)
    # twice the SNR needs twice the amplitude (the SNR is linear in it)
    rec2, _ = oven_record(tmp_path, "ool_case2", seed=16, theta=THETA)
    got2 = add_out_of_library(rec2, ool, 80.0, dev, [(0.0, 1.0, 1.0)] * 5)
    assert abs(got2["amplitude_dps"] / got["amplitude_dps"] - 2.0) < 1e-9


def test_out_of_library_fraction_leaves_the_other_cases_alone(tmp_path):
    for f in (-0.1, 1.0, float("nan")):
        with pytest.raises(MixError) as e:
            CaseMix.build(ool_fraction=f)
        assert e.value.field == "ool"
    mix = CaseMix.build(ool_fraction=0.5)
    # which cases of seed 4242 are out of library is decided by their own random stream
    is_ool = [np.random.default_rng([4242, k, 1]).random() < 0.5 for k in range(8)]
    k_in, k_out = is_ool.index(False), is_ool.index(True)
    a = make_case(k_in, 4242, tmp_path / "a", str(NOMINAL), duration_s=1.1 * 3600.0)
    b = make_case(k_in, 4242, tmp_path / "b", str(NOMINAL), duration_s=1.1 * 3600.0, mix=mix)
    assert {k: v for k, v in a.items() if k != "record"} == {k: v for k, v in b.items() if k != "record"}
    o = make_case(k_out, 4242, tmp_path / "o", str(NOMINAL), duration_s=1.1 * 3600.0, mix=mix)
    assert o["effects"] == {} and o["out_of_library"]["kind"] in ("bias_wander", "bias_step")
    assert abs(o["snr"] / o["snr_target"] - 1.0) < 1e-9 or o["out_of_library"]["amplitude_dps"] == 2.0
    assert o["tier"] == tier(o["snr"]) and "noise_model" in o


def test_a_case_unit_is_drawn_across_every_knob_and_its_record_goes_through_its_channels(tmp_path):
    """The benchmark's units differ from the nominal device in values, temperature laws, channel offsets and gains
    and the quadrature's sign, each within its tolerance, as the diagnosis expects of a real unit (not the
    simulator's own nominal model)."""
    knobs = KnobSet.of(load_scenario(NOMINAL).device_nominal)
    lab = make_case(1, 7, tmp_path, str(NOMINAL), duration_s=1.1 * 3600.0, mix=CaseMix.build(kind="single",
                                                                                              effects=["thermal_lag"]))
    theta = lab["nominal_deviation"]
    assert set(theta) == set(knobs.names) and lab["quadrature_sign"] in (-1.0, 1.0)
    assert all(abs(theta[n]) <= t for n, t in zip(knobs.names, knobs.tolerance))
    assert {k.group for k in knobs.knobs if theta[k.name] != 0.0} == {"unit", "law", "channel"}
    # the record as the unit's data acquisition writes it: channel gains and offsets, rate_dps over the nominal SF
    cols = {"time_s": np.arange(5.0), "temperature_C": np.linspace(20, 24, 5), "rate_V": np.full(5, 0.01),
            "quadrature_V": np.full(5, 1.0), "rate_dps": np.zeros(5)}
    th = {"quadrature_gain_rel": 0.1, "quadrature_offset_V": 0.02, "rate_offset_V": -0.01, "temperature_delay_s": 1.0}
    rec = recorded(type(read_record(lab["record"]))(cols, {}), th, 0.009)
    assert np.allclose(rec.columns["quadrature_V"], 1.12) and np.allclose(rec.columns["rate_V"], 0.0)
    assert np.allclose(rec.columns["rate_dps"], 0.0) and np.allclose(rec.columns["temperature_C"][1:], [20, 21, 22, 23])
    assert apply_channels({"split_Hz": 3.0}, cols) == cols
    dev = load_scenario(NOMINAL).device_nominal
    flipped = unit_device({"quadrature_sign": -1.0}, dev)
    assert flipped.values["mechanics"]["quadrature_rate_dps"] == -dev.values["mechanics"]["quadrature_rate_dps"]
    assert unit_device({}, dev) is dev
