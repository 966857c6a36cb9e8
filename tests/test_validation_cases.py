"""The diagnosis on simulated records whose effect is withheld: null, one effect, two effects, gaps/NaNs."""

import json

import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.diagnosis.pipeline import diagnose
from fmvmg_sim.record import read_record, write_record
from tests.test_diagnosis_helpers import LATE_RAMP, NOMINAL, oven_record

THETA = {"q_sense_rel": 0.1, "quadrature_rel": -0.08, "demod_phase_mrad": 1.0, "f_modes_rel": 0.002,
         "q_drive_rel": -0.1}


def test_null_record_gives_none(tmp_path):
    rec, _ = oven_record(tmp_path, "null", seed=11, theta=THETA)
    rep = diagnose(rec, NOMINAL, n_null=3, progress=False)
    assert rep["verdict"] == "none", [(r["effect"], r.get("heldout_gain_ci"), r.get("delta_bic"))
                                      for r in rep["ranked"][:3]]
    assert rep["accepted"] == []
    # the null replicates are exchangeable with a record that has no gap: each is read against its own
    # calibration, as the record is, so the located statistics sit inside the null's spread (the replicates
    # read against the record's calibration put the rate regimes at z -3.5 to -5 here)
    for g in ("allan_bands", "regimes"):
        for name, d in rep["localization"][g].items():
            assert abs(d["z"]) < 3, (g, name, d["z"])
    # every candidate says which criterion it fails
    assert all(r["why_not"] for r in rep["ranked"]), [(r["effect"], r.get("why_not")) for r in rep["ranked"]]


def test_thermal_lag_attributed_with_gaps_and_nans(tmp_path, capsys):
    rec, _ = oven_record(tmp_path, "lag", {"thermal_lag": {"tau_s": 600.0, "offset_K": 0.4}}, seed=12, theta=THETA)
    r = read_record(rec)
    keep = np.ones(len(r), bool)
    keep[3000:3300] = False  # a 5 min gap
    cols = {k: v[keep].copy() for k, v in r.columns.items()}
    cols["quadrature_V"][100:110] = np.nan
    cols["rate_dps"][5000] = np.nan
    r2 = type(r)(cols, r.metadata)
    write_record(tmp_path / "lag_gaps.csv", r2)
    out = tmp_path / "out"
    rc = main(["diagnose", str(tmp_path / "lag_gaps.csv"), "--scenario", str(NOMINAL), "-o", str(out), "--json",
               "--null-runs", "3", "--no-progress"])
    assert rc == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep == json.loads((out / "report.json").read_text())
    assert rep["verdict"] in ("explained", "ambiguous") and rep["accepted"][0] == "thermal_lag"
    top = rep["ranked"][0]
    assert top["effect"] == "thermal_lag" and top["accepted"] and "why_not" not in top
    assert abs(top["params"]["tau_s"] - 600.0) / 600.0 < 0.10          # stated tolerance: 10 %
    assert top["shrink"] > 0.5
    assert rep["record"]["issues"]["gaps"] and rep["record"]["issues"]["nan_samples"]["quadrature_V"] == 10
    # the oven's last hold (50 C) lies beyond every temperature the last fold trained on; the first fold is
    # tested on the heating ramp's lower part, inside the range it trained on (25 to -10 C)
    folds = rep["record"]["folds"]
    assert folds[0]["test_outside_fraction"] == 0.0 and folds[-1]["test_outside_fraction"] == 1.0
    assert rep["record"]["heldout_outside_training_temperatures"]["heldout_outside_max_K"] > 4.0
    assert "outside their fold's training temperatures" in (out / "report.md").read_text()
    for f in ("report.md", "residual_time.png", "residual_temperature.png", "allan.png", "gap_before_after.png"):
        assert (out / f).is_file()
    assert set(rep["localization"]) >= {"channels", "allan_bands", "regimes"}


def test_demod_phase_drift_attributed(tmp_path):
    rec, _ = oven_record(tmp_path, "phase", {"demod_phase_drift": {"kappa_urad_per_K": 200.0}}, seed=13, theta=THETA)
    rep = diagnose(rec, NOMINAL, n_null=3, progress=False)
    assert rep["accepted"][:1] == ["demod_phase_drift"], [(r["effect"], r["accepted"]) for r in rep["ranked"][:4]]
    top = rep["ranked"][0]
    assert abs(top["params"]["kappa_urad_per_K"] - 200.0) / 200.0 < 0.15  # stated tolerance: 15 %
    assert top["shrink"] > 0.5
    # the drift is where the gap lies (the bias differs between heating and cooling), and the accepted
    # model closes it there: no remainder
    assert rep["verdict"] in ("explained", "ambiguous") and rep["remainder"] is None
    checked = rep["closure"]["checked"]
    assert checked and rep["closure"]["open"] == [] and all(c["shrink"] > 0.5 for c in checked), checked


@pytest.mark.slow
def test_library_effect_beside_an_out_of_library_step_is_partial(tmp_path):
    # the same phase drift, plus a 0.3 deg/s bias step at 60 % of the record that no library effect makes: the
    # phase drift still passes, but the gap where it lies stays open (shrink below one half, still beyond the
    # null band), so the verdict is "unexplained", with the phase drift as the part it explains
    rec, _ = oven_record(tmp_path, "phase", {"demod_phase_drift": {"kappa_urad_per_K": 200.0}}, seed=13, theta=THETA)
    r = read_record(rec)
    cols = {k: v.copy() for k, v in r.columns.items()}
    t = cols["time_s"]
    step_dps = 0.3 * np.clip((t - 0.6 * t[-1]) / 60.0, 0.0, 1.0)
    sf = np.nanmedian(cols["rate_V"] / np.where(cols["rate_dps"] != 0, cols["rate_dps"], np.nan))
    cols["rate_dps"] = cols["rate_dps"] + step_dps
    cols["rate_V"] = cols["rate_V"] + step_dps * sf
    write_record(tmp_path / "phase_step.csv", type(r)(cols, r.metadata))
    out = tmp_path / "out"
    rc = main(["diagnose", str(tmp_path / "phase_step.csv"), "--scenario", str(NOMINAL), "-o", str(out),
               "--null-runs", "3", "--no-progress"])
    assert rc == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["verdict"] == "unexplained" and rep["accepted"][:1] == ["demod_phase_drift"], rep["accepted"]
    rem = rep["remainder"]
    assert rem["partial"] and rem["explained_by"][:1] == ["demod_phase_drift"]
    opened = rep["closure"]["open"]
    assert opened and all(c["shrink"] < 0.5 and c["p_holm_after"] < 0.05 for c in opened)
    assert {s["name"] for s in rem["significant"]} == {c["name"] for c in opened}
    assert "do not close the gap where it lies" in (out / "report.md").read_text()


@pytest.mark.slow
def test_two_effects(tmp_path):
    eff = {"thermal_lag": {"tau_s": 900.0, "offset_K": 0.3}, "demod_phase_drift": {"kappa_urad_per_K": -120.0}}
    rec, _ = oven_record(tmp_path, "pair", eff, seed=14, theta=THETA)
    rep = diagnose(rec, NOMINAL, n_null=3, progress=False)
    assert sorted(rep["accepted"]) == sorted(eff), rep["accepted"]


@pytest.mark.slow
@pytest.mark.parametrize("wander_amp_dps", [0.05, 0.10])
def test_out_of_library_gap_is_unexplained(tmp_path, wander_amp_dps):
    # a bias wander no library effect makes (a 50 min sine in time, unrelated to temperature): the
    # diagnosis must not force a library effect onto it, and must say where the gap lies. The stronger
    # one lifts the flicker band as much as flicker would; its excess rises as tau^2, so it is no flicker.
    # The weaker one is located only by a null read as the record is, against its own calibration (read
    # against the record's calibration, its rate regimes were at z -5 to -8 and the verdict "none")
    rec, _ = oven_record(tmp_path, "ool", seed=15, theta=THETA)
    r = read_record(rec)
    cols = {k: v.copy() for k, v in r.columns.items()}
    wander_dps = wander_amp_dps * np.sin(2 * np.pi * cols["time_s"] / 3000.0)
    sf = np.nanmedian(cols["rate_V"] / np.where(cols["rate_dps"] != 0, cols["rate_dps"], np.nan))
    cols["rate_dps"] = cols["rate_dps"] + wander_dps
    cols["rate_V"] = cols["rate_V"] + wander_dps * sf
    write_record(tmp_path / "ool_wander.csv", type(r)(cols, r.metadata))
    rep = diagnose(tmp_path / "ool_wander.csv", NOMINAL, n_null=3, progress=False)
    assert rep["accepted"] == [], [(x["effect"], x["accepted"], x.get("heldout_gain_ci")) for x in rep["ranked"][:4]]
    hmc = rep["localization"]["regimes"]["heating_minus_cooling_rate_V"]
    assert rep["verdict"] == "unexplained", (hmc, rep["localization"]["regimes"])
    groups = {s["group"] for s in rep["remainder"]["significant"]}
    assert groups & {"allan_bands", "regimes"}
    if wander_amp_dps > 0.05:
        flicker = next(r for r in rep["ranked"] if r["effect"] == "flicker_noise")
        assert flicker["detail"]["z_heldout"] > 3 and "tau^2" in flicker["why_not"][0], flicker


def test_signature_snr_counts_the_records_slow_noise(tmp_path):
    # the detection limit is in units of the record's noise: a white model reproduces the white-noise
    # SNR exactly, and the rate output's flicker wander (the noise model of a noise-only twin) lowers the
    # SNR of a slow rate-channel signature (a temperature-rate term follows the oven, not the noise)
    from fmvmg_sim.validation.cases import noise_model, signature_snr
    from fmvmg_sim.scenario import load_scenario
    rec, _ = oven_record(tmp_path, "twin", seed=21, theta=THETA)
    dev = load_scenario(NOMINAL).device_nominal
    eff = {"temperature_rate": {"g_dph_per_K_per_min": 60.0}}
    white = signature_snr(rec, NOMINAL, dev, THETA, eff)
    assert white > 10
    assert abs(signature_snr(rec, NOMINAL, dev, THETA, eff, noise=[(0.0, 1.0, 1.0)] * 5) / white - 1) < 1e-9
    noise = noise_model(read_record(rec), dev, THETA)
    rho, K, s = noise[0]                                    # rate channel: a slow state under white noise
    assert rho > 0.8 and K < 0.6
    coloured = signature_snr(rec, NOMINAL, dev, THETA, eff, noise=noise)
    assert coloured < 0.5 * white
    # a drive-frequency signature (Duffing), where the block sigma is a model floor: never credited
    # beyond its white-noise SNR
    duff = {"duffing": {"k3_rel": 3e-6}}
    assert signature_snr(rec, NOMINAL, dev, THETA, duff, noise=noise) <= signature_snr(rec, NOMINAL, dev, THETA, duff)
    # aiming a Duffing term at an SNR its oscillation cannot reach backs off instead of failing the case
    from fmvmg_sim.validation.cases import _scale_to
    scale, snr = _scale_to(rec, NOMINAL, dev, THETA, {"duffing": {"k3_rel": 3e-4}}, 800.0, noise=noise)
    assert scale > 1.0 and 0 < snr < 800.0


@pytest.mark.xfail(strict=True, reason=("with the AGC effort the exact mean over each sample, the Q drift's own SNR on this record "
    "reads 38 (under the 50 the test needs), and at twice the size its SNR beyond the reference drift exceeds its own: "
    "the case generator's SNRs are redone with the calibration's rework"))
def test_separable_snr_is_what_the_partner_cannot_explain(tmp_path):
    # a Q drift and a reference drift both move the AGC effort (u ~ A/Q): beside each other, each keeps a
    # fraction of its own SNR; a temperature-rate term follows the oven's ramps, which a quadrature drift
    # (a law in temperature) cannot mimic, so it keeps its own; beside a noise level nothing is absorbed
    from fmvmg_sim.validation.cases import noise_model, separable_snr, signature_snr
    from fmvmg_sim.scenario import load_scenario
    rec, _ = oven_record(tmp_path, "twin", seed=21, theta=THETA)
    dev = load_scenario(NOMINAL).device_nominal
    noise = noise_model(read_record(rec), dev, THETA)
    look_alikes = {"q_factor_drift": {"q_tc_per_K": 3e-5},
                   "reference_drift": {"vref_tc_per_K": 2e-6, "rectifier_mV_per_K": 0.01}}
    distinct = {"temperature_rate": {"g_dph_per_K_per_min": 600.0}, "quadrature_drift": {"beta_per_K": 1e-4}}
    for eff in (look_alikes, distinct):
        own = {n: signature_snr(rec, NOMINAL, dev, THETA, {n: v}, noise=noise) for n, v in eff.items()}
        assert min(own.values()) > 50
        sep = separable_snr(rec, dev, THETA, eff, noise, own)
        if eff is look_alikes:
            assert all(sep[n] < 0.3 * own[n] for n in eff), (own, sep)
        else:
            assert abs(sep["temperature_rate"] / own["temperature_rate"] - 1) < 0.01, (own, sep)
    # the truth beyond an answer: nothing explained is the signature's own SNR; the look-alike explains most
    # of a Q drift, an unrelated effect none of it
    from fmvmg_sim.validation.cases import snr_beyond
    q = {"q_factor_drift": look_alikes["q_factor_drift"]}
    own_q = signature_snr(rec, NOMINAL, dev, THETA, q, noise=noise)
    assert abs(snr_beyond(rec, dev, THETA, q, noise, []) / own_q - 1) < 1e-9
    assert snr_beyond(rec, dev, THETA, q, noise, ["reference_drift"]) < 0.3 * own_q
    assert snr_beyond(rec, dev, THETA, q, noise, ["temperature_rate", "quantization"]) > 0.95 * own_q
    with_noise = {"temperature_rate": {"g_dph_per_K_per_min": 600.0}, "quantization": {"lsb_V": 0.005}}
    own = {"temperature_rate": 60.0, "quantization": 32.0}
    assert separable_snr(rec, dev, THETA, with_noise, noise, own) == own
    single = {"temperature_rate": {"g_dph_per_K_per_min": 600.0}}
    assert separable_snr(rec, dev, THETA, single, noise, {"temperature_rate": 60.0}) == {"temperature_rate": 60.0}


def test_training_snr_is_what_the_training_window_carries(tmp_path):
    # a temperature-rate term acts only while the oven ramps: with the record's one ramp in its held-out end
    # (the last fold's test segment starts at 80 % of the record, its training ends at 76 %), the diagnoser's
    # training window carries none of it, however high the whole-record SNR; with the ramps early, most of it
    from fmvmg_sim.validation.cases import noise_model, signature_snr, training_snr
    from fmvmg_sim.scenario import load_scenario
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
    from fmvmg_sim.diagnosis.attribute import bound_check
    from fmvmg_sim.validation.cases import scaled
    eff = scaled({"stress_relaxation": {"quad_rel": -0.1, "tau_h": 20.0}}, 5.0)
    assert -0.2 < eff["stress_relaxation"]["quad_rel"] <= -0.19 and eff["stress_relaxation"]["tau_h"] == 20.0
    assert bound_check(eff) == (None, [])
    assert bound_check({"stress_relaxation": {"quad_rel": -0.2, "tau_h": 20.0}}) == (None, ["stress_relaxation.quad_rel"])


def test_case_mix_checks_its_choices():
    from fmvmg_sim.validation.cases import P_NULL, P_SINGLE, SNR_TARGET, CaseMix, MixError
    from fmvmg_sim.effects import MODELS
    d = CaseMix.build()
    assert d == CaseMix() and d.effects == tuple(MODELS) and (d.p_null, d.p_single) == (P_NULL, P_SINGLE)
    assert d.snr_range == SNR_TARGET
    # library order, duplicates dropped
    m = CaseMix.build(["reference_drift", "q_factor_drift", "reference_drift"], "single", 10.0, 1000.0)
    assert m.effects == ("q_factor_drift", "reference_drift") and (m.p_null, m.p_single) == (0.0, 1.0)
    assert CaseMix.build(["duffing", "feedthrough"], "pair").p_single == 0.0
    for args, field in [((["q_drift"],), "effects"), (([],), "effects"), ((None, "triple"), "kind"), ((["duffing"], "default"), "effects"),
                        ((None, "single", 0.0, 10.0), "snr"), ((None, "single", 10.0, 10.0), "snr"),
                        ((None, "single", 1.0, float("inf")), "snr")]:
        with pytest.raises(MixError) as e:
            CaseMix.build(*args)
        assert e.value.field == field, (args, e.value.field)
    assert "q_factor_drift" in str(pytest.raises(MixError, CaseMix.build, ["q_drift"]).value)   # lists the known ones


def test_a_narrow_mix_draws_single_effects_from_its_pool(tmp_path):
    from fmvmg_sim.validation.cases import CaseMix, make_case
    mix = CaseMix.build(["q_factor_drift", "reference_drift"], "single", 10.0, 1000.0)
    for k in range(2):
        lab = make_case(k, 60221, tmp_path, str(NOMINAL), duration_s=1.1 * 3600.0, mix=mix)
        assert len(lab["effects"]) == 1 and set(lab["effects"]) <= set(mix.effects)
        assert 10.0 <= lab["snr_target"] <= 1000.0
    # the default mix draws the same case as before the mix existed (no mix given)
    a = make_case(5, 4242, tmp_path / "a", str(NOMINAL), duration_s=1.1 * 3600.0)
    b = make_case(5, 4242, tmp_path / "b", str(NOMINAL), duration_s=1.1 * 3600.0, mix=CaseMix())
    assert {k: v for k, v in a.items() if k != "record"} == {k: v for k, v in b.items() if k != "record"}


def test_out_of_library_disturbances(tmp_path):
    # a unit sine in time, and a step from 0 to 1 that is half-way at its time and done within its rise
    from fmvmg_sim.validation.cases import OUT_OF_LIBRARY, out_of_library_shape
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
    from fmvmg_sim.averaged import scale_factor_V_per_dps
    from fmvmg_sim.validation.cases import add_out_of_library, out_of_library_shape
    from fmvmg_sim.diagram import build_diagram
    from fmvmg_sim.scenario import load_scenario
    rec, _ = oven_record(tmp_path, "ool_case", seed=16, theta=THETA)
    before = read_record(rec)
    dev = load_scenario(NOMINAL).device_nominal
    sf = scale_factor_V_per_dps(build_diagram(dev, dev.reference_temperature_C))
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
    from fmvmg_sim.validation.cases import CaseMix, MixError, make_case
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
    from fmvmg_sim.validation.cases import tier
    assert o["tier"] == tier(o["snr"]) and "noise_model" in o


def test_a_gap_in_one_channel_alone_is_unexplained_not_none(tmp_path):
    # a hysteresis seen only on the record's last ramp, inside the last held-out block: no training window
    # holds it, so no effect can be fitted and scored, but the quadrature output is far off the null there.
    # The verdict names that channel ("unexplained"), where it used to say "none" (here quadrature at
    # z 13.8, Holm p 0.005; benchmark seed 69314 case 27: z 24.5 and a verdict of "none")
    late_ramp = """
[temperature]
start_C = 22.0
segments = [
  { hold_s = 9000.0 },
  { ramp_to_C = 47.0, rate_C_per_min = 1.0 },
]
"""
    rec, _ = oven_record(tmp_path, "late", {"thermal_hysteresis": {"quad_rel": 5e-3, "width_K": 7.0}}, seed=27,
                         theta=THETA, profile=late_ramp, duration_s=10800.0)
    rep = diagnose(rec, NOMINAL, n_null=4, progress=False, log=lambda m: None)
    assert rep["accepted"] == [], rep["accepted"]
    assert rep["verdict"] == "unexplained"
    names = [(s["group"], s["name"]) for s in rep["remainder"]["significant"]]
    assert ("channels", "quadrature_V") in names, names
    # fitted on the whole record (a hint, never accepted), the withheld hysteresis closes it best, with its
    # parameters (here 0.00503 and 7.13 K; in-sample Delta-BIC -8.7e5 against -8.1e5 for a quadrature drift)
    best = rep["in_sample_candidates"]["candidates"][0]
    assert best["effect"] == "thermal_hysteresis", rep["in_sample_candidates"]
    assert abs(best["params"]["quad_rel"] / 5e-3 - 1) < 0.1 and abs(best["params"]["width_K"] / 7.0 - 1) < 0.1
    assert "not an attribution" in rep["in_sample_candidates"]["note"]
    from fmvmg_sim.diagnosis.report import write_report
    md = (write_report(rep, tmp_path / "rep") and (tmp_path / "rep" / "report.md").read_text())
    assert "## In-sample candidates (not an attribution)" in md and "- thermal_hysteresis: Delta-BIC" in md


def test_coarse_converter_is_scored_through_its_staircase(tmp_path):
    """A mode-split drift read through a converter 30 times coarser than the output noise: the report names the
    converter (its step read off the record, its dithering noise off the null, far below the step), and the drift
    is found with its look-alike (a quadrature drift carries the same quadrature signature on an oven record)."""
    eff = {"quantization": {"lsb_V": 0.01}, "mode_split_drift": {"split_Hz_per_K": 0.05}}
    rec, _ = oven_record(tmp_path, "coarse", eff, seed=31, theta=THETA)
    rep = diagnose(rec, NOMINAL, n_null=3, progress=False, log=lambda m: None)
    conv = rep["record"]["converter"]
    assert set(conv) == {"rate_V", "quadrature_V"}
    for c in conv.values():
        assert c["lsb_V"] == pytest.approx(0.01, rel=1e-6)
        assert 0 < c["noise_V"] < 0.1 * c["lsb_V"]
    found = set(rep["accepted"]) | {x for v in rep["ambiguous_with"].values() for x in v}
    assert rep["accepted"][0] == "quantization" and "mode_split_drift" in found, (rep["accepted"],
                                                                                  rep["ambiguous_with"])
    from fmvmg_sim.diagnosis.report import markdown
    assert "Read through a coarse converter" in markdown(rep)
    # the held-out gains are in nats per block, finite (a misread block costs a bounded amount)
    row = next(r for r in rep["ranked"] if r["effect"] == "mode_split_drift")
    assert 1.0 < row["heldout_gain"] < 100.0


def test_a_partial_single_effect_gives_way_to_a_stronger_pair(tmp_path):
    # benchmark case 90015/12 (regenerated from its seed): a feedthrough and a phase drift, each of SNR ~1000,
    # fail alone on each other's signature, and a quadrature drift passes alone with the located gap left open
    # (a partial "unexplained"); the pair fitted from scratch gains ten times more held out and is the truth
    from fmvmg_sim.validation.cases import make_case
    lab = make_case(12, 90015, tmp_path, str(NOMINAL))
    assert sorted(lab["effects"]) == ["demod_phase_drift", "feedthrough"] and lab["tier"] == "above"
    rep = diagnose(lab["record"], NOMINAL, n_null=4, progress=False)
    assert sorted(rep["accepted"]) == ["demod_phase_drift", "feedthrough"], (rep["accepted"], rep["verdict"])
    assert rep["replaced_partial"] == "quadrature_drift" and rep["verdict"] == "explained"
    row = next(r for r in rep["ranked"] if r["effect"] == "quadrature_drift")
    assert not row["accepted"] and "pair fitted from scratch" in row["why_not"][0]


@pytest.mark.xfail(strict=True, reason="the shipped device's amplifier-bandwidth TC is now the physics brief's low end (-0.2 %/K): this record, drawn for the former device, no longer sets up what the test guards; to be replaced with the calibration's rework")
def test_a_pair_that_leaves_the_located_gap_open_does_not_replace_the_single_effect(tmp_path):
    # benchmark case 90556/5 (one effect per case, regenerated from its seed): a Q drift of SNR 585 passes alone with
    # the cooling regime left open (shrink 0.10); a reference drift without its Vref part beside a mode-split drift,
    # fitted from scratch, gains 0.77 nats a block more held out but leaves the same regime open with the same
    # shrink. It is no better account of where the gap lies, so the Q drift stands (session 47's rule; before it,
    # the pair replaced the truth)
    from fmvmg_sim.validation.cases import CaseMix, make_case
    lab = make_case(5, 90556, tmp_path, str(NOMINAL), mix=CaseMix.build(kind="single"))
    assert list(lab["effects"]) == ["q_factor_drift"] and lab["tier"] == "above"
    rep = diagnose(lab["record"], NOMINAL, n_null=4, progress=False, log=lambda m: None)
    assert rep["accepted"] == ["q_factor_drift"], (rep["accepted"], rep["verdict"])
    assert rep["replaced_partial"] is None
    assert sorted(rep["pair_left_gap_open"]) == ["mode_split_drift", "reference_drift"]
    # the gap stays open either way: a partial verdict, with the look-alike named
    assert rep["verdict"] == "unexplained" and [s["name"] for s in rep["closure"]["open"]] == ["cooling"]
    assert rep["ambiguous_with"] == {"q_factor_drift": ["reference_drift"]}
    from fmvmg_sim.diagnosis.report import markdown
    assert "A pair fitted from scratch (reference_drift + mode_split_drift) gains more held out" in markdown(rep)


@pytest.mark.xfail(strict=True, reason="the shipped device's amplifier-bandwidth TC is now the physics brief's low end (-0.2 %/K): this record, drawn for the former device, no longer sets up what the test guards; to be replaced with the calibration's rework")
def test_a_located_gap_is_named_by_an_effect_that_fails_only_the_fold_count(tmp_path):
    # benchmark case 90001/22 (regenerated from its seed): a feedthrough of SNR 62 on a record whose first training
    # window holds one temperature and whose second fold is tested wholly by extrapolation; its pooled held-out
    # interval is above zero but its one testable fold does not pass alone, and nothing else passes. The
    # localisation finds the gap (quadrature channel), so the feedthrough names it, flagged as weaker evidence
    from fmvmg_sim.validation.cases import make_case
    from fmvmg_sim.diagnosis.report import markdown
    lab = make_case(22, 90001, tmp_path, str(NOMINAL))
    assert list(lab["effects"]) == ["feedthrough"] and lab["tier"] == "above"
    rep = diagnose(lab["record"], NOMINAL, n_null=4, progress=False)
    assert rep["accepted"] == ["feedthrough"] and rep["located_gap"] == "feedthrough", (rep["accepted"], rep["verdict"])
    row = next(r for r in rep["ranked"] if r["effect"] == "feedthrough")
    assert "fold count" in row["accepted_on"] and row["heldout_gain"] > 0
    assert "names a gap the localisation found" in markdown(rep)
