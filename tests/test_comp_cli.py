"""``fmvmg compensate``: outputs as docs/formats.md gives them, exit 2 on bad input."""

import json

import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.compensation.synthetic import make_record
from fmvmg_sim.record import read_record, write_record


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("comp")
    # a full up-and-down ramp: a one-way ramp has constant dT/dt, confounded with the bias
    write_record(d / "train.csv", make_record(7200, 10, "ramp", "static", seed=1))
    write_record(d / "test.csv", make_record(1800, 10, "cooling", "static", seed=2))
    return d


def test_held_out_poly_baseline_json(files, capsys):
    rc = main(["compensate", str(files / "test.csv"), "--method", "poly-baseline", "--train",
               str(files / "train.csv"), "-o", str(files / "out"), "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res["method"] == "poly-baseline" and res["in_sample"] is False
    for side in ("before", "after"):
        assert {"arw_deg_per_sqrt_h", "bias_instability_deg_per_h", "truth_rms_dps"} <= set(res[side])
    assert res["after"]["residual_drift_rms_dph"] < 0.5 * res["before"]["residual_drift_rms_dph"]
    out = read_record(files / "out" / "compensated.csv")
    src = read_record(files / "test.csv")
    np.testing.assert_allclose(out["rate_raw_dps"], src["rate_dps"], rtol=1e-11)
    np.testing.assert_allclose(out["temperature_C"], src["temperature_C"], rtol=1e-11)
    assert out.metadata["compensation_method"] == "poly-baseline" and out.metadata["in_sample"] == "false"
    assert not np.allclose(out["rate_dps"], src["rate_dps"])


def test_in_sample_pipeline_json(files, capsys):
    rc = main(["compensate", str(files / "test.csv"), "--method", "emd-rbf", "-o", str(files / "ins"),
               "--json", "--no-progress"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res["in_sample"] is True and res["fit_diagnostics"]["n_imfs"] >= 3
    assert (files / "ins" / "compensation.json").is_file()


def test_bad_inputs_exit_2(files, capsys, tmp_path):
    rec = read_record(files / "test.csv")
    keep = np.ones(len(rec), bool)
    keep[3000:3050] = False
    write_record(tmp_path / "gappy.csv", rec.slice(keep))
    write_record(tmp_path / "short.csv", rec.slice(slice(0, 500)))
    (tmp_path / "notemp.csv").write_text("time_s,rate_dps\n0,1\n0.1,2\n")
    nan = rec.slice(slice(None))
    nan.columns["temperature_C"] = nan["temperature_C"].copy()
    nan.columns["temperature_C"][10] = np.nan
    write_record(tmp_path / "nan.csv", nan)
    cases = [("gappy.csv", "emd-rbf", "uneven steps"), ("short.csv", "emd-rbf-ga", "needs at least"),
             ("notemp.csv", "poly-baseline", "temperature_C"), ("nan.csv", "poly-baseline", "missing/NaN"),
             ("test.csv", "no-such-method", "unknown method")]
    for name, method, msg in cases:
        rc = main(["compensate", str(tmp_path / name if name != "test.csv" else files / name), "--method", method,
                   "-o", str(tmp_path / "o"), "--no-progress"])
        err = capsys.readouterr().err
        assert rc == 2 and msg in err and "Traceback" not in err, (name, err)
    assert main(["compensate", str(tmp_path / "gappy.csv"), "--method", "poly-baseline", "-o",
                 str(tmp_path / "g"), "--json"]) == 0  # poly-baseline handles gaps
