"""The paper-000 pipeline on small synthetic records (5 Hz, 40 min: one entropy segment per IMF)."""

import numpy as np
import pytest

from fmvmg_sim.compensation import get_method
from fmvmg_sim.compensation.ga import ga_budget
from fmvmg_sim.compensation.kalman import cutoff_Hz, steady_state_gain
from fmvmg_sim.compensation.synthetic import make_record
from fmvmg_sim.errors import InputError

SMALL_GA = {"ga_population": 8, "ga_generations": 4, "ga_rows": 2000}


@pytest.fixture(scope="module")
def runs():
    train = make_record(2400, 5, "heating", "static", seed=1)
    test = make_record(2400, 5, "heating", "static", seed=2)
    return train, test


@pytest.fixture(scope="module")
def fitted(runs):
    return get_method("emd-rbf-ga-kf")(**SMALL_GA).fit(runs[0])


def _drift_rms_dph(rec, y):
    err = y - rec["rate_true_dps"]
    return float(np.sqrt(np.mean(err.reshape(-1, 500).mean(1) ** 2)) * 3600)  # 100 s means


def test_held_out_drift_is_reduced_and_everything_is_reported(runs, fitted):
    train, test = runs
    comp = fitted
    out = comp.compensate_rate_dps(test)
    before, after = _drift_rms_dph(test, test["rate_dps"]), _drift_rms_dph(test, out)
    assert before > 60 and after < 0.3 * before
    d = comp.fit_diagnostics_
    cls = [c.split()[0] for c in d["classes"]]
    assert len(cls) == d["n_imfs"] + 1 and cls[-1] == "drift"
    rank = {"noise": 0, "mixed": 1, "drift": 2}
    assert all(rank[a] <= rank[b] for a, b in zip(cls, cls[1:]))  # monotone in IMF index
    assert comp.transform_diagnostics_["rbf"]["ga"]["n_evals"] == ga_budget(8, 4, 2)  # fitted on the record
    kf = d["kf"]
    assert kf["steady_gain"] == pytest.approx(steady_state_gain(kf["q"], kf["r"]))
    assert kf["cutoff_Hz"] == pytest.approx(cutoff_Hz(kf["steady_gain"], 5.0), rel=1e-9)
    assert 0.0 <= comp.transform_diagnostics_["dropped_noise_variance_fraction"] <= 1.0
    assert comp.transform_diagnostics_["temperature_trend"]["decimation"] == 5


def test_in_sample_fit_transform_matches_fit_then_transform(runs):
    rec = runs[0].slice(slice(0, 6000))
    a = get_method("emd-rbf")().fit_transform(rec)["rate_dps"]
    b = get_method("emd-rbf")().fit(rec).compensate_rate_dps(rec)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_refuses_gaps_nan_and_short_records(runs, fitted):
    train, _ = runs
    comp = get_method("emd-rbf-ga")(**SMALL_GA)
    keep = np.ones(len(train), bool)
    keep[5000:5100] = False
    with pytest.raises(InputError, match="uneven steps"):
        comp.fit(train.slice(keep))
    bad = train.slice(slice(None))
    bad.columns["rate_dps"] = bad["rate_dps"].copy()
    bad.columns["rate_dps"][7] = np.nan
    with pytest.raises(InputError, match="rate_dps has 1 missing"):
        comp.fit(bad)
    with pytest.raises(InputError, match="needs at least 2000"):
        comp.fit(train.slice(slice(0, 1500)))
    with pytest.raises(InputError, match="uneven steps"):  # transform checks too
        fitted.compensate_rate_dps(train.slice(keep))
