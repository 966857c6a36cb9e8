"""``fmvmg compensate``: outputs as docs/formats.md gives them, exit 2 on bad input."""

import json

import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.compensation.synthetic import DriftParams, make_record
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
    # the pipeline low-passes its output: no -1/2 region is left, and its "bias instability" is marked
    assert res["before"]["allan_validity"]["bias_instability_valid"] is True
    after = res["after"]["allan_validity"]
    assert after["arw_valid"] is False and after["bias_instability_valid"] is False
    assert "white-noise" in after["reasons"]["bias_instability"]
    assert res["selection"]["chosen"]  # the drift model's selection is reported
    assert res["baselines"]["held_out"] is False
    main(["compensate", str(files / "test.csv"), "--method", "emd-rbf", "-o", str(files / "ins2"), "--no-progress"])
    text = capsys.readouterr().out
    assert "(not valid*)" in text and "* not valid after, bias instability" in text


def test_default_method_and_baselines(tmp_path, capsys):
    """Without --method the selected polynomial runs; a held-out run is set beside a bias and a line in T."""
    quiet = DriftParams(arw_dph_per_rtHz=5.0, bias_instability_dph=1.0, a2_dph_per_C2=0.5)  # a curved law
    write_record(tmp_path / "train.csv", make_record(7200, 10, "ramp", "static", seed=1, params=quiet))
    write_record(tmp_path / "test.csv", make_record(1800, 10, "cooling", "static", seed=2, params=quiet))
    files = tmp_path
    rc = main(["compensate", str(files / "test.csv"), "--train", str(files / "train.csv"), "-o",
               str(files / "def"), "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res["method"] == "poly-baseline"
    b = res["baselines"]
    assert b["held_out"] is True and set(b["rms_dps"]) == {"poly-baseline", "bias", "line", "white_noise_floor"}
    # the synthetic drift has T^2 and dT/dt laws: the selected polynomial beats both references
    assert b["best"] == "poly-baseline" and b["rms_dps"]["poly-baseline"] < b["rms_dps"]["line"]
    assert b["rms_dps"]["white_noise_floor"] < b["rms_dps"]["poly-baseline"]
    assert res["selection"]["chosen"] and res["extrapolation"] is not None
    # a plain bias calibration is beaten by the line, and the report says so
    main(["compensate", str(files / "test.csv"), "--method", "bias", "--train", str(files / "train.csv"), "-o",
          str(files / "bias")])
    assert "a line in T beats bias on this record" in capsys.readouterr().out


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
             ("notemp.csv", "poly-baseline", "temperature_C"), ("nan.csv", "emd-rbf", "missing/NaN"),
             ("test.csv", "no-such-method", "unknown method")]
    for name, method, msg in cases:
        rc = main(["compensate", str(tmp_path / name if name != "test.csv" else files / name), "--method", method,
                   "-o", str(tmp_path / "o"), "--no-progress"])
        err = capsys.readouterr().err
        assert rc == 2 and msg in err and "Traceback" not in err, (name, err)
    assert main(["compensate", str(tmp_path / "gappy.csv"), "--method", "poly-baseline", "-o",
                 str(tmp_path / "g"), "--json"]) == 0  # poly-baseline handles gaps
    capsys.readouterr()
    assert main(["compensate", str(tmp_path / "nan.csv"), "-o", str(tmp_path / "n"), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)  # ... and rows with a missing value, as gaps
    assert any("data row 11" in n for n in res["notes"])
    assert np.isnan(read_record(tmp_path / "n" / "compensated.csv")["rate_dps"][10])
