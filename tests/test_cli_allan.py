"""``fmvmg allan``: JSON and table output, -o files, exit code 2 with the line for bad input."""

from __future__ import annotations

import json
import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.output import MARKER

FS = 100.0
N_DPS_SQRT_S = 1.66 / 60.0


def _write(path, t, y, header="time_s,rate_dps", extra=None):
    rows = [f"{a:.12g},{b:.12g}" + ("" if extra is None else f",{extra[i]:.12g}") for i, (a, b) in enumerate(zip(t, y))]
    path.write_text("# source: test\n" + header + "\n" + "\n".join(rows).replace("nan", "") + "\n")
    return path


@pytest.fixture
def white_record(tmp_path):
    rng = np.random.default_rng(21)
    n = 20_000
    y = rng.standard_normal(n) * N_DPS_SQRT_S * np.sqrt(FS)
    temp = 25.0 + 0.01 * rng.standard_normal(n)
    return _write(tmp_path / "rec.csv", np.arange(n) / FS, y, "time_s,rate_dps,temperature_C", temp)


def test_json_is_one_object_with_the_keys(white_record, capsys):
    assert main(["allan", str(white_record), "--json"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1
    d = json.loads(out)
    for key in ("taus_s", "adev", "adev_lo", "adev_hi", "n_clusters", "slopes", "arw_deg_per_sqrt_h",
                "bias_instability_deg_per_h", "bias_instability_ieee952_deg_per_h", "tau_min_s",
                "rrw_deg_per_h_sqrt_h", "rrw", "column", "fs_Hz", "bias_instability_definition"):
        assert key in d, key
    assert d["column"] == "rate_dps" and d["fs_Hz"] == 100.0 and d["taus_s"][0] == 0.01
    assert d["arw_deg_per_sqrt_h"] == pytest.approx(1.66, rel=0.05)
    assert d["bias_instability_ieee952_deg_per_h"] == pytest.approx(d["bias_instability_deg_per_h"] / 0.664)
    assert "allan_minimum" in d["bias_instability_definition"]


def test_table_and_output_dir(white_record, tmp_path, capsys):
    out_dir = tmp_path / "out"
    assert main(["allan", str(white_record), "-o", str(out_dir), "--taus", "dense"]) == 0
    text = capsys.readouterr().out
    assert "ARW  N = " in text and "deg/sqrt(h)" in text and "Allan minimum" in text
    d = json.loads((out_dir / "allan.json").read_text())
    assert len(d["taus_s"]) > 30  # dense taus
    assert (out_dir / "allan.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in out_dir.iterdir()) == [MARKER, "allan.json", "allan.png"]


def test_other_column_uses_its_unit(white_record, capsys):
    assert main(["allan", str(white_record), "--column", "temperature_C", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["unit"] == "degC" and d["arw_deg_per_sqrt_h"] is None
    assert d["N_unit_sqrt_s"] == pytest.approx(0.01 / np.sqrt(FS), rel=0.05)


def test_non_monotonic_time_exits_2_with_line(tmp_path, capsys):
    p = tmp_path / "bad.csv"
    p.write_text("# x: y\ntime_s,rate_dps\n0,1\n0.1,2\n\n0.2,3\n0.15,4\n0.3,5\n")
    assert main(["allan", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fmvmg: error: ") and err.count("\n") == 1
    assert f"{p} line 7" in err and "time_s" in err and "Traceback" not in err


def test_gap_refused_without_resample_and_accepted_with_it(tmp_path, capsys):
    n = 4000
    t = np.arange(n) / FS
    t[2000:] += 0.05  # 5 samples missing
    y = np.random.default_rng(1).standard_normal(n)
    p = _write(tmp_path / "gap.csv", t, y)
    assert main(["allan", str(p), "--json"]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and f"{p} line 2003" in cap.err and "--resample" in cap.err
    assert main(["allan", str(p), "--json", "--resample"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["resampled"] is True and d["n_samples"] == n + 5 and d["n_filled"] == 5
    t[3000:] += 1.0  # a 1 s gap: beyond the 10-step limit even with --resample
    p = _write(tmp_path / "biggap.csv", t, y)
    assert main(["allan", str(p), "--resample"]) == 2
    assert f"{p} line 3003" in capsys.readouterr().err


def test_missing_column_and_missing_file(white_record, tmp_path, capsys):
    assert main(["allan", str(white_record), "--column", "quadrature_V"]) == 2
    err = capsys.readouterr().err
    assert f"{white_record} line 2" in err and "quadrature_V" in err and "missing required column" in err
    assert main(["allan", str(tmp_path / "absent.csv")]) == 2
    assert "absent.csv: file not found" in capsys.readouterr().err


def test_needs_only_time_and_the_column_and_fills_short_nan_runs(tmp_path, capsys):
    y = np.random.default_rng(2).standard_normal(3000)
    y[100:102] = np.nan
    p = _write(tmp_path / "min.csv", np.arange(3000) / FS, y)
    assert main(["allan", str(p), "--json"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["n_filled"] == 2 and "filled by linear interpolation" in cap.err
    y[200:210] = np.nan
    p = _write(tmp_path / "min2.csv", np.arange(3000) / FS, y)
    assert main(["allan", str(p)]) == 2
    assert f"{p} line 203" in capsys.readouterr().err


@pytest.mark.parametrize("n", [3, 7])
def test_a_record_too_short_for_any_allan_estimate_is_refused(tmp_path, capsys, n):
    y = np.random.default_rng(3).standard_normal(n)
    p = _write(tmp_path / "short.csv", np.arange(n) / FS, y)
    assert main(["allan", str(p), "--json", "-o", str(tmp_path / "o")]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and "not enough data" in cap.err and f"{n} samples" in cap.err
    assert len(cap.err.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_the_shortest_accepted_record_reads_its_minimum_at_the_first_tau(tmp_path, capsys):
    y = np.random.default_rng(3).standard_normal(8)
    p = _write(tmp_path / "eight.csv", np.arange(8) / FS, y)
    assert main(["allan", str(p), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["n_clusters"][0] == 8 and d["arw_deg_per_sqrt_h"] is None


def test_a_byte_order_mark_is_accepted(white_record, capsys):
    assert main(["allan", str(white_record), "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    bom = white_record.with_name("bom.csv")
    bom.write_bytes(b"\xef\xbb\xbf" + white_record.read_bytes())  # as spreadsheet programs write UTF-8
    assert main(["allan", str(bom), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["adev"] == plain["adev"]


def test_a_folder_given_as_the_record_is_named_as_such(tmp_path, capsys):
    assert main(["allan", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "is a folder; expected a record file" in err and "not found" not in err
