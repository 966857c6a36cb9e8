"""BMI270 PuTTY logs to records: corrupted lines, time base, columns; Allan on the real logs."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from fmvmg_sim.analysis import allan_deviation, series_from_record
from fmvmg_sim.cli.main import main
from fmvmg_sim.errors import InputError
from fmvmg_sim.io.bmi270 import read_bmi270_log
from fmvmg_sim.record import RecordWarning, read_record

DATA = Path(__file__).resolve().parent / "data"  # copies of outside reference data, with provenance and licence
REAL = DATA / "real-bmi270"

SYNTH = """=~=~=~=~=~=~=~=~=~=~=~= PuTTY log 2026.05.08 15:02:51 =~=~=~=~=~=~=~=~=~=~=~=
0.003,-0.032,0.73,0.12,-1.10
13.25,0.075,0.018,-0.241,-0.12,-1.34,-0.18
13.26,0.075,0.023,-0.243,0.00,-0.73,-0.31
13.27,0.075,0.018,-0.242,0.12,-0.3-0.31,-0.18
13.28,0.074,0.023,-0.244,-0.18,0.18,-0.06
13.29,047.306641,0.248,0.026,-0.029,0.31,-0.18,0.06
13.30,0.076,0.019,-0.243,0.00,-1.10,0.25
1"""


def test_synthetic_log_rules(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text(SYNTH)
    imp = read_bmi270_log(p, axis="y")
    rec = imp.record
    assert [s.line for s in imp.skipped] == [2, 5, 7, 9]
    reasons = [s.reason for s in imp.skipped]
    assert reasons[0].startswith("before the first good sample: 5 comma-separated cells")
    assert "cell 6 (gyro_y_dps) '-0.3-0.31' is not a number" in reasons[1]
    assert reasons[2] == "8 comma-separated cells, expected 7"
    assert reasons[3].startswith("after the last good sample")
    # lines 3..8 are six 50 Hz slots; the two corrupted ones inside are missing rows
    np.testing.assert_allclose(rec.time_s, np.arange(6) * 0.02)
    np.testing.assert_array_equal(np.isnan(rec["rate_dps"]), [0, 0, 1, 0, 1, 0])
    np.testing.assert_allclose(rec["rate_dps"][[0, 1, 3, 5]], [-1.34, -0.73, 0.18, -1.10])
    np.testing.assert_allclose(rec["gyro_x_dps"][[0, 5]], [-0.12, 0.0])
    np.testing.assert_allclose(rec["gyro_z_dps"][[0, 5]], [-0.18, 0.25])
    np.testing.assert_allclose(rec["accel_x_g"][0], 0.3)  # 0.075 * 4
    np.testing.assert_allclose(rec["temperature_C"][[0, 5]], [13.25, 13.30])
    assert "rate_dps" in rec and "gyro_y_dps" not in rec
    assert imp.n_missing == 2 and rec.metadata["skipped_lines"] == "2,5,7,9"


def test_bad_inputs(tmp_path):
    p = tmp_path / "junk.csv"
    p.write_text("=~=~= PuTTY log =~=~=\nhello\n1,2,3\n")
    with pytest.raises(InputError, match="no BMI270 sample line"):
        read_bmi270_log(p)
    with pytest.raises(InputError, match="axis"):
        read_bmi270_log(p, axis="w")
    with pytest.raises(InputError, match="file not found"):
        read_bmi270_log(tmp_path / "absent.csv")


def test_cli_import_writes_a_readable_record(tmp_path, capsys):
    log = tmp_path / "log.csv"
    log.write_text(SYNTH)
    out = tmp_path / "rec.csv"
    assert main(["import-bmi270", str(log), "-o", str(out), "--axis", "x", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_samples"] == 6 and summary["n_missing"] == 2 and summary["axis"] == "x"
    assert [s["line"] for s in summary["skipped"]] == [2, 5, 7, 9]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordWarning)  # gyro_*/accel_* are extra columns
        rec = read_record(out)
    assert rec.metadata["device"] == "bmi270"
    np.testing.assert_allclose(rec["rate_dps"][[0, 5]], [-0.12, 0.0])
    assert main(["import-bmi270", str(tmp_path / "absent.csv"), "-o", str(out)]) == 2
    assert "absent.csv: file not found" in capsys.readouterr().err


@pytest.mark.parametrize("name, skipped, n_rows", [
    ("BMI_270_cold_test_.csv", [9, 3258], 3256),
    ("BMI_270_hot_test.csv", [2, 13, 6537], 6534),
])
def test_real_logs_convert(name, skipped, n_rows):
    imp = read_bmi270_log(REAL / name)
    assert [s.line for s in imp.skipped] == skipped
    assert len(imp.record) == n_rows and imp.n_missing == 1
    assert imp.record.time_s[-1] == pytest.approx((n_rows - 1) / 50.0)


def test_real_cold_log_allan(tmp_path):
    imp = read_bmi270_log(REAL / "BMI_270_cold_test_.csv", axis="z")
    s = series_from_record(imp.record, "rate_dps")
    assert s.fs_Hz == 50.0 and s.n_filled == 1
    res = allan_deviation(s.values, s.fs_Hz)
    assert res.taus_s[0] == 0.02 and res.adev[0] == pytest.approx(0.1782, rel=1e-3)
    assert -0.6 < res.slopes[0] < -0.4                                  # white at short tau, no -1 slope
    assert res.arw_deg_per_sqrt_h == pytest.approx(1.263, rel=1e-3)               # white term, 0.16 s to the minimum
    assert res.white.region_s == pytest.approx((0.16, 5.12))
    assert res.bias_instability_deg_per_h == pytest.approx(26.34, rel=1e-3)
    assert any("upper bound" in n for n in res.notes)                # 65 s: still falling at T/8
    assert res.rrw is None


def test_real_hot_log_steep_short_tau():
    imp = read_bmi270_log(REAL / "BMI_270_hot_test.csv", axis="z")
    s = series_from_record(imp.record, "rate_dps")
    res = allan_deviation(s.values, s.fs_Hz)
    slope_first_octave = np.log(res.adev[1] / res.adev[0]) / np.log(2.0)
    assert slope_first_octave < -1.2                     # steeper than white noise at 0.02-0.04 s
    assert res.alpha[0] == 2                              # lag-1 ACF says white-PM-like there
    q_white_dps = 0.061 / np.sqrt(12.0)                   # rate quantisation, per sample
    assert res.adev[0] > 20 * q_white_dps                 # ...but far above the 0.061 dps quantum
