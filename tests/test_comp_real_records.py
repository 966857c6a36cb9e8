"""Compensation on measured records the project did not make (tests/data): held out, beside the baselines.

The LSM6DSM thermal-vacuum record is a record of 5 s bursts every 305 s, cooling 8 K; the BMI270
logs are two static soaks 35 K apart. Figures are held-out RMS over the RMS a bias calibration
from the training part leaves.
"""

import warnings
from pathlib import Path

import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.compensation import get_method
from fmvmg_sim.compensation.baselines import rms_dps, white_noise_floor_dps
from fmvmg_sim.compensation.physics import PhysicsFallbackWarning
from fmvmg_sim.io.bmi270 import read_bmi270_log
from fmvmg_sim.record import read_record, write_record
from fmvmg_sim.validation.compensation_records import (Case, evaluate_case, halves, load_records, make_cases,
                                                       markdown, target_check)

DATA = Path(__file__).resolve().parent / "data"
LSM = DATA / "real-lsm6dsm-tvac"


@pytest.fixture(scope="module")
def lsm():
    return {ax: read_record(LSM / f"lsm6dsm_tvac_{ax}.csv") for ax in "yz"}


def ratio(method, train, test, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        comp = get_method(method)(**kw).fit(train)
        out = comp.compensate_rate_dps(test)
    bias = get_method("bias")().fit(train).compensate_rate_dps(test)
    return rms_dps(test, out) / rms_dps(test, bias), comp


@pytest.mark.parametrize("reverse", [False, True])
def test_lsm6dsm_y_drift_removed_to_near_the_noise_floor(lsm, reverse):
    a, b = halves(lsm["y"])
    train, test = (b, a) if reverse else (a, b)
    floor = white_noise_floor_dps(test) / rms_dps(test, get_method("bias")().fit(train).compensate_rate_dps(test))
    for method in ("poly-baseline", "physics"):
        r, comp = ratio(method, train, test)
        assert r <= 0.25, (method, r)
        assert r < 1.1 * floor  # within 10 % of what a perfect drift model would leave
    r, comp = ratio("poly-baseline", train, test)
    d = comp.diagnostics_
    # 5 s bursts: no dT/dt over 60 s or more exists, and the validation takes the line
    assert d["selection"]["chosen"] == "order 1" and d["sampling"]["bursty"]
    assert all(c["settings"]["dTdt_smoothing_s"] is None for c in d["selection"]["candidates"])
    ex = comp.transform_diagnostics_["extrapolation"]["variables"]["temperature_C"]
    assert (ex["above"] if reverse else ex["below"]) == pytest.approx(4.0, abs=0.5)


def test_lsm6dsm_default_within_5_percent_of_line_and_polynomial(lsm):
    for rec in lsm.values():
        a, b = halves(rec)
        for train, test in ((a, b), (b, a)):
            default = ratio("poly-baseline", train, test)[0]
            line = ratio("line", train, test)[0]
            assert default <= 1.05 * min(line, default)


def test_lsm6dsm_physics_falls_back_to_the_temperature_model(lsm):
    a, b = halves(lsm["y"])
    with pytest.warns(PhysicsFallbackWarning, match="none of the auxiliary channels"):
        phys = get_method("physics")().fit(a)
    poly = get_method("poly-baseline")().fit(a)
    assert phys.diagnostics_["fallback_temperature_only"]
    np.testing.assert_allclose(phys.compensate_rate_dps(b), poly.compensate_rate_dps(b))


def test_lsm6dsm_decomposition_methods_refuse_bursts(capsys, tmp_path):
    for method in ("emd-rbf", "vmd-wflp-cssvr"):
        rc = main(["compensate", str(LSM / "lsm6dsm_tvac_y.csv"), "--method", method, "--no-progress",
                   "-o", str(tmp_path / method)])
        err = capsys.readouterr().err
        assert rc == 2 and "25 bursts of about 5 s every 305 s" in err and "Traceback" not in err
        assert not (tmp_path / method).exists()  # nothing half-written


def test_lsm6dsm_held_out_report_names_the_line(lsm, tmp_path, capsys):
    a, b = halves(lsm["y"])
    write_record(tmp_path / "a.csv", a)
    write_record(tmp_path / "b.csv", b)
    assert main(["compensate", str(tmp_path / "b.csv"), "--train", str(tmp_path / "a.csv"), "-o",
                 str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "does as well as a line in T" in out and "4.06 degC below the training range" in out


def test_bmi270_one_soak_applied_to_the_other(tmp_path):
    """Fitted on a 0.3 K soak at 13 C and applied at 48 C: the model must not extrapolate a noise slope 35 K."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cold = read_bmi270_log(DATA / "real-bmi270" / "BMI_270_cold_test_.csv", axis="z").record
        hot = read_bmi270_log(DATA / "real-bmi270" / "BMI_270_hot_test.csv", axis="z").record
    r_poly, comp = ratio("poly-baseline", cold, hot)
    r_line, _ = ratio("line", cold, hot)
    assert r_line > 5.0          # a line fitted on 0.3 K of noise, extrapolated 35 K
    assert r_poly <= 1.05        # the selected model holds at the edge of its range instead
    ex = comp.transform_diagnostics_["extrapolation"]
    if "temperature_C" in ex["variables"]:  # a model with a temperature term: reported and held
        assert ex["variables"]["temperature_C"]["above"] == pytest.approx(36.1, abs=1.0)
        assert "dT" in ex["held"]
    else:  # or the selection took no temperature term at all
        assert not any(t == "dT" or t.startswith("dT^") for t in comp.diagnostics_["terms"])


def test_records_harness_on_the_test_copies():
    records, skipped = load_records(DATA)
    names = {r.name for r in records}
    assert "real-lsm6dsm-tvac/lsm6dsm_tvac_y" in names and "real-bmi270/BMI_270_hot_test[x]" in names
    assert len(records) == 8 and "allan-reference" in skipped
    cases = make_cases(records)
    assert len(cases) == 8 * 2 + 3 * 2  # both halves of each, and cold x hot per BMI270 axis, both ways
    case = next(c for c in cases if c.record.endswith("lsm6dsm_tvac_y") and c.direction.startswith("1st"))
    evaluate_case(case, ("poly-baseline", "line", "emd-rbf"))
    assert case.results["emd-rbf"]["refused"].startswith("the record is made of 13 bursts")
    assert case.results["poly-baseline"]["ratio"] == pytest.approx(case.results["line"]["ratio"])
    assert target_check(case)["ok"] is True
    table = markdown([case], ("poly-baseline", "line", "emd-rbf"))
    assert "refused [1]" in table and "[1] the record is made of 13 bursts" in table
    assert isinstance(case, Case)
