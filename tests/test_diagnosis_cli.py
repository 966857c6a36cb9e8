"""``fmvmg diagnose`` bad input: exit 2 with a message naming what is wrong."""

import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.diagnosis.fitting import Fitter
from fmvmg_sim.diagnosis.pipeline import library_bias_dps, load_inputs
from fmvmg_sim.errors import InputError
from fmvmg_sim.scenario import load_scenario
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
    assert rc == 2 and "rate_dps" in err and "quadrature_V" in err
    # without rate_V and quadrature_V, only the bias tells: refused beyond what any library effect makes
    del cols["quadrature_V"]
    cols["rate_dps"] = cols["rate_dps"] + 1e5
    rec.columns = cols
    write_record(tmp_path / "mdps3.csv", rec)
    with pytest.raises(InputError, match="library effect"):
        load_inputs(tmp_path / "mdps3.csv", NOMINAL)


def test_large_admissible_bias(tmp_path, good):
    """A rate bias of 300 deg/s is 30x beyond the nominal device's scale, but a feedthrough inside the library's
    range (about 12 fF at the nominal scale factor) makes it: the record is diagnosed, not refused."""
    rec = read_record(good)
    cols = dict(rec.columns)
    sf = load_scenario(NOMINAL).device_nominal.nominal_scale_factor_V_per_dps
    cols["rate_dps"] = cols["rate_dps"] + 300.0
    cols["rate_V"] = cols["rate_V"] + 300.0 * sf
    rec.columns = cols
    write_record(tmp_path / "ft.csv", rec)
    _, prep = load_inputs(tmp_path / "ft.csv", NOMINAL)
    assert prep.n_blocks > 0
    fitter = Fitter(prep, load_scenario(NOMINAL).device_nominal)
    nominal = fitter.table({}).evaluate(fitter.path(None)["die_b"], fitter.rate_b)
    # the feedthrough at its 100 fF bound makes thousands of deg/s at the nominal scale factor
    assert 1000.0 < library_bias_dps(fitter, nominal) < 1e4
