"""``fmvmg diagnose`` bad input: exit 2 with a message naming what is wrong."""

import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.record import read_record, write_record
from tests.test_diagnosis_helpers import NOMINAL, oven_record


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("diag_cli")
    rec, _ = oven_record(tmp, "good", seed=2)
    return rec


def _run(capsys, *args):
    rc = main(["diagnose", *map(str, args), "--scenario", str(NOMINAL), "--no-plots", "--no-progress"])
    return rc, capsys.readouterr().err


def test_missing_column(tmp_path, capsys):
    p = tmp_path / "r.csv"
    p.write_text("time_s,rate_dps\n0.1,0.0\n0.2,0.0\n")
    rc, err = _run(capsys, p, "-o", tmp_path / "o")
    assert rc == 2 and "temperature_C" in err and "r.csv" in err


def test_header_without_rows(tmp_path, capsys):
    # named in our words, with no numpy warning leaking onto the terminal before it
    p = tmp_path / "r.csv"
    p.write_text("time_s,temperature_C,rate_dps\n")
    rc, err = _run(capsys, p, "-o", tmp_path / "o")
    assert rc == 2 and "no data rows" in err and "r.csv" in err
    assert "warning" not in err and not (tmp_path / "o").exists()


def test_non_monotonic_time(tmp_path, capsys):
    p = tmp_path / "r.csv"
    p.write_text("time_s,temperature_C,rate_dps\n0.1,25,0.0\n0.3,25,0.0\n0.2,25,0.0\n")
    rc, err = _run(capsys, p, "-o", tmp_path / "o")
    assert rc == 2 and "line 4" in err and "increasing" in err


def test_too_short(tmp_path, capsys, good):
    rec = read_record(good)
    write_record(tmp_path / "short.csv", rec.slice(slice(0, 1200)))
    rc, err = _run(capsys, tmp_path / "short.csv", "-o", tmp_path / "o")
    assert rc == 2 and "needs at least" in err


def test_rate_thousand_times_off(tmp_path, capsys, good):
    rec = read_record(good)
    cols = dict(rec.columns)
    cols["rate_dps"] = cols["rate_dps"] * 1000.0  # milli-degrees per second written as deg/s
    rec.columns = cols
    write_record(tmp_path / "mdps.csv", rec)
    rc, err = _run(capsys, tmp_path / "mdps.csv", "-o", tmp_path / "o")
    assert rc == 2 and "rate_dps" in err and "wrong unit" in err
    # without rate_V the magnitude check catches it too
    del cols["rate_V"]
    rec.columns = cols
    write_record(tmp_path / "mdps2.csv", rec)
    rc, err = _run(capsys, tmp_path / "mdps2.csv", "-o", tmp_path / "o")
    assert rc == 2 and "rate_dps" in err
