"""The ``vmd-wflp-cssvr`` compensator (paper 004) on synthetic records."""

import numpy as np
import pytest

from fmvmg_sim.compensation import get_method
from fmvmg_sim.compensation.synthetic import make_record
from fmvmg_sim.compensation.vmd_wflp_cssvr import VMDWFLPCSSVR
from fmvmg_sim.errors import InputError
from fmvmg_sim.record import Record

FAST = dict(budget=10, n_nests=5, n_max=150)  # tiny CS-SVR search to keep the suite fast


def rms_dph(x):
    return float(np.sqrt(np.mean(np.asarray(x) ** 2))) * 3600.0


@pytest.fixture(scope="module")
def fitted():
    # 1 Hz, 2 h: at this rate the thermal drift owns the lowest VMD mode (at 100 Hz it would not)
    train = make_record(duration_s=7200, fs_Hz=1.0, profile="heating", seed=1)
    return VMDWFLPCSSVR(residual="drop", **FAST).fit(train)


def test_registered():
    assert get_method("vmd-wflp-cssvr") is VMDWFLPCSSVR


def test_fit_diagnostics(fitted):
    d = fitted.fit_diagnostics_
    assert d["classes"][0] == "drift" and d["classes"][1:] == ["noise"] * 5
    assert len(d["centre_frequencies_Hz"]) == 6 and d["centre_frequencies_Hz"][0] < 0.005
    assert len(d["sample_entropy"]) == 6 and d["sample_entropy"][0] < 0.25
    assert 0.3 < d["residual_fraction"] < 0.6
    assert d["cssvr"]["nfev"] == 10 and fitted.C_ > 0 and fitted.sigma_ > 0


def test_compensates_held_out_heating_run(fitted):
    test = make_record(duration_s=7200, fs_Hz=1.0, profile="heating", seed=2)
    truth = test["rate_true_dps"]
    raw_err = rms_dph(test["rate_dps"] - truth)
    out = fitted.compensate_rate_dps(test)
    assert out.shape == (len(test),)
    d = fitted.transform_diagnostics_
    assert d["drift_model_subtracted"] and d["residual_policy"] == "drop"
    assert d["n_modes"] == {"noise": 5, "mixed": 0, "drift": 1}
    # raw error ~170 deg/h (offset + thermal drift + noise); compensated drift mode alone is far smaller
    assert rms_dph(out - truth) < 0.5 * raw_err


def test_residual_policies_are_explicit(fitted):
    test = make_record(duration_s=3600, fs_Hz=1.0, profile="heating", seed=3)
    outs = {}
    for pol in ("drop", "keep", "wflp"):
        outs[pol] = fitted.set_params(residual=pol).compensate_rate_dps(test)
    fitted.set_params(residual="drop")
    diff = outs["keep"] - outs["drop"]
    # "keep" adds back exactly the VMD residual, a large broadband share of the input
    assert 0.3 < np.std(diff) / np.std(test["rate_dps"]) < 0.6
    assert np.std(outs["wflp"] - outs["drop"]) < np.std(diff)
    with pytest.raises(ValueError):
        VMDWFLPCSSVR(residual="ignore").fit(test)


def test_no_drift_mode_means_no_model():
    rng = np.random.default_rng(0)
    n = 2000
    t = np.arange(n, dtype=float)
    rec = Record({"time_s": t, "temperature_C": np.full(n, 25.0), "rate_dps": rng.standard_normal(n)})
    m = VMDWFLPCSSVR(**FAST).fit(rec)
    assert m.svr_ is None and "not fitted" in m.fit_diagnostics_["cssvr"]
    out = m.compensate_rate_dps(rec)
    assert not m.transform_diagnostics_["drift_model_subtracted"]
    assert out.shape == (n,)


def test_refuses_gaps():
    rec = make_record(duration_s=600, fs_Hz=1.0, seed=0)
    keep = np.ones(len(rec), bool)
    keep[300:320] = False
    with pytest.raises(InputError, match="uneven"):
        VMDWFLPCSSVR(**FAST).fit(rec.slice(keep))


@pytest.fixture(scope="module")
def fitted_100Hz():
    """Trained at the simulator's 100 Hz: the chain runs on 1 Hz block means (decimate_Hz=1)."""
    train = make_record(duration_s=7200, fs_Hz=100.0, profile="heating", seed=1)
    return VMDWFLPCSSVR(**FAST).fit(train)


def test_decimated_chain_at_100Hz_compensates_held_out(fitted_100Hz):
    m = fitted_100Hz
    d = m.fit_diagnostics_
    assert m.block_ == 100 and d["decimated_to_Hz"] == pytest.approx(1.0) and d["n_samples_full_rate"] == 720_000
    assert d["classes"][0] == "drift" and m.svr_ is not None
    test = make_record(duration_s=7200, fs_Hz=100.0, profile="heating", seed=2)
    truth = test["rate_true_dps"]

    def drift(x):  # RMS of 100 s means of the error, deg/h
        e = (np.asarray(x) - truth).reshape(-1, 10_000).mean(1)
        return float(np.sqrt(np.mean(e ** 2)) * 3600)

    out_all = m.set_params(carry_back="all").compensate_rate_dps(test)
    td = m.transform_diagnostics_
    assert td["drift_model_subtracted"] and td["carry_back"] == "all" and td["decimation_block"] == 100
    assert td["filter_time_constant_s"] > 0.1  # the dropped noise modes filter the band below 0.5 Hz
    # the band above the 1 Hz rate's Nyquist passes unchanged: it is most of the white noise
    assert td["full_rate_residual_rms_dps"] > 0.9 * np.std(test["rate_dps"] - truth - np.mean(test["rate_dps"]))
    out_drift = m.set_params(carry_back="drift").compensate_rate_dps(test)
    assert m.transform_diagnostics_["filter_time_constant_s"] == 0.0
    m.set_params(carry_back="all")
    raw = drift(test["rate_dps"])
    assert drift(out_all) < 0.5 * raw and drift(out_drift) < 0.5 * raw
    # carry_back="drift" only subtracts a slow correction (no filtering of the signal path)
    corr = test["rate_dps"] - out_drift
    assert np.std(np.diff(corr)) < 1e-2 * np.std(np.diff(test["rate_dps"]))
    with pytest.raises(ValueError):
        VMDWFLPCSSVR(carry_back="some").fit(test)


def test_too_short_for_the_decimated_chain():
    rec = make_record(duration_s=200, fs_Hz=100.0, seed=0)
    with pytest.raises(InputError, match="blocks"):
        VMDWFLPCSSVR(**FAST).fit(rec)
