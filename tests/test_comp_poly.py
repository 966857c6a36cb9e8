"""poly-baseline: recovers a known thermal model, handles gaps, refuses bad records."""

import numpy as np
import pytest

from fmvmg_sim.compensation import get_method
from fmvmg_sim.compensation.poly import check_record, thermal_features
from fmvmg_sim.compensation.synthetic import DriftParams, make_record
from fmvmg_sim.errors import InputError

QUIET = DriftParams(arw_dph_per_rtHz=1.0, bias_instability_dph=0.0, rrw_dph_per_rts=0.0, temp_noise_C=0.0)


def test_recovers_thermal_coefficients_and_generalises():
    train = make_record(7200, 10, "ramp", "sines", seed=0, params=QUIET)  # heating alone: T and dT/dt collinear
    test = make_record(7200, 10, "cooling", "sines", seed=1, params=QUIET)
    comp = get_method("poly-baseline")().fit(train)
    c = comp.coef_ * 3600  # deg/h units
    dT_ref = comp.T_ref_C_ - 25.0
    assert c[3] == pytest.approx(25.0, rel=0.05)                 # c, deg/h per degC/min
    assert c[2] == pytest.approx(0.02, rel=0.1)                  # a2
    assert c[1] == pytest.approx(2.0 + 2 * 0.02 * dT_ref, rel=0.05)  # a1 about T_ref
    err = comp.transform(test) - test["rate_true_dps"]
    raw = test["rate_dps"] - test["rate_true_dps"]
    assert np.sqrt(np.mean(err**2)) < 0.1 * np.sqrt(np.mean(raw**2))


def test_handles_gaps():
    rec = make_record(3600, 10, "heating", "static", seed=2)
    keep = np.ones(len(rec), bool)
    keep[10000:13000] = False  # a 300 s gap
    gappy = rec.slice(keep)
    comp = get_method("poly-baseline")()
    assert comp.handles_gaps
    out = comp.fit(gappy).transform(gappy)
    assert out.shape == (len(gappy),) and np.all(np.isfinite(out))
    with pytest.raises(InputError, match="uneven steps"):
        check_record(gappy, need_uniform=True, method="emd-rbf")


def test_refuses_nan_temperature():
    rec = make_record(100, 10, "soak", "static", seed=0)
    rec.columns["temperature_C"][5] = np.nan
    with pytest.raises(InputError, match="temperature_C has 1 missing"):
        get_method("poly-baseline")().fit(rec)


def test_thermal_features_derivative():
    t = np.arange(0, 600.0, 0.1)
    F = thermal_features(t, 20 + 0.5 * t / 60, 20.0)  # 0.5 degC/min ramp
    assert F[3000:-3000, 2] == pytest.approx(0.5, rel=1e-6)
    assert F[3000, 0] == pytest.approx(0.5 * t[3000] / 60, abs=0.01)
