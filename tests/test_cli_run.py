"""``fmvmg run`` as a user runs it: outputs, bad scenarios (exit 2), loop failures reported, not crashed."""

import json
from pathlib import Path

import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.record import read_record
from fmvmg_sim.record import RECORD_ORDER


def test_run_writes_record_summary_and_plots(make_scenario, tmp_path, capsys):
    path = make_scenario(duration_s=0.3, output_rate_Hz=1000.0, noise=True, state="rest")
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out), "--json", "--no-progress"]) == 0
    summary = json.loads(capsys.readouterr().out)
    for key in ("drive_amplitude_V", "drive_frequency_Hz", "settling_time_s", "scale_factor_V_per_dps",
                "zero_rate_bias_dps", "wall_time_s", "simulated_time_s", "steps_per_cycle"):
        assert key in summary
    assert summary["steps_per_cycle"] == 32
    rec = read_record(out / "record.csv")
    assert set(RECORD_ORDER) <= set(rec.columns)
    for name in RECORD_ORDER:
        assert np.isfinite(rec[name][1:]).all(), name  # every channel filled (frequency needs one interval)
    assert rec.metadata["source"] == "simulation"
    assert (out / "startup.png").stat().st_size > 1000 and (out / "channels.png").stat().st_size > 1000
    assert json.loads((out / "summary.json").read_text())["status"] == "ok"


def test_set_overrides_any_value(make_scenario, tmp_path, capsys):
    path = make_scenario(duration_s=0.05)
    assert main(["run", str(path), "-o", str(tmp_path / "o"), "--json", "--no-plots",
                 "--set", "circuit.reference.vref_V=0.5", "--set", "scenario.duration_s=0.04"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["simulated_time_s"] == pytest.approx(0.04, abs=1e-3)
    assert s["drive_amplitude_setpoint_V"] == pytest.approx(0.5, rel=1e-9)


BAD = [
    ("[scenario]\nduration_sec = 1\n", "scenario.duration_sec"),                   # unknown key (wrong unit)
    ('[scenario]\nduration_s = "10 min"\n', "scenario.duration_s"),                 # value with a unit in it
    ("[scenario]\nduration_s = 1\n[device.mechanics]\nq_drive = -5\n", "device.mechanics.q_drive"),  # negative Q
    ('[scenario]\nduration_s = 1\ndevice_file = "nope.toml"\n', "scenario.device_file"),  # missing device file
    ("[scenario]\nduration_s = 1\n[temperature]\npoints = [[0, 25], [10, 30], [5, 40]]\n", "temperature.points"),
    ("[scenario]\nduration_s = 1\n[temperature]\nsegments = [{hold_s = -3}]\n", "temperature.segments[0].hold_s"),
    ("[scenario]\nduration_s = 1\nseed = 1.5\n", "scenario.seed"),
    ("[scenario]\nduration_s = 1\n[noise]\nflicker = 1\n", "noise.flicker"),
    ("[scenario]\nduration_s = 1\n[effects]\nthermal_lagg = {}\n", "effects.thermal_lagg"),
    ("[scenario]\nduration_s = 1\n[circuit.pi]\nkpp = 3\n", "circuit.pi.kpp"),
    ("[scenaro]\nduration_s = 1\n", "scenaro"),
    ("[scenario\nduration_s = 1\n", "not valid TOML"),
]


@pytest.mark.parametrize("text,where", BAD, ids=[w for _, w in BAD])
def test_bad_scenarios_exit_2_naming_the_key(tmp_path, capsys, text, where):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    assert main(["run", str(p), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert where in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o" / "record.csv").exists()


def test_bad_set_override_exits_2(make_scenario, tmp_path, capsys):
    path = make_scenario()
    assert main(["run", str(path), "--set", "circuit.pi.kp=fast", "-o", str(tmp_path / "o")]) == 2
    assert "circuit.pi.kp" in capsys.readouterr().err
    assert main(["run", str(path), "--set", "nonsense", "-o", str(tmp_path / "o")]) == 2
    assert main(["run", str(tmp_path / "missing.toml")]) == 2


@pytest.mark.parametrize("override, key", [
    ("circuit.pi.kp=fast", "circuit.pi.kp"),                      # a circuit value (validated with the device)
    ("device.mechanics.q_drive=-5", "device.mechanics.q_drive"),  # a device value
    ("scenario.duration_s=-1", "scenario.duration_s"),            # a scenario value
    ("temperature.segments=[{hold_s=-3}]", "temperature.segments[0].hold_s"),  # inside a profile
    ("effects.thermal_lag.tau_s=1e9", "effects.thermal_lag.tau_s"),            # an effect parameter
    ("scenario.device_file=nope", "scenario.device_file"),
])
def test_a_bad_set_is_blamed_on_the_set_argument_not_the_scenario_file(make_scenario, tmp_path, capsys,
                                                                        override, key):
    path = make_scenario()
    assert main(["run", str(path), "--set", "scenario.seed=3", "--set", override, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"fmvmg: error: --set {override}: {key}: "), err
    assert str(path) not in err


def test_a_bad_value_in_the_file_is_still_blamed_on_the_file(make_scenario, tmp_path, capsys):
    path = make_scenario(body="[circuit.pi]\nkp = -1\n")
    assert main(["run", str(path), "--set", "circuit.pi.ki_per_s=100", "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{path}: " in err and "circuit.pi.kp" in err and "--set" not in err


def test_a_folder_given_as_the_scenario_is_named_as_such(tmp_path, capsys):
    assert main(["run", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err


def test_a_shipped_scenario_runs_by_name(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "startup", "--set", "scenario.duration_s=0.02", "--no-plots", "--json", "-o", "o"]) == 0
    assert json.loads(capsys.readouterr().out)["simulated_time_s"] == pytest.approx(0.02, abs=1e-3)
    assert main(["run", "no_such_scenario"]) == 2
    assert "shipped scenarios: " in capsys.readouterr().err


def test_a_loop_that_cannot_reach_its_setpoint_is_reported(make_scenario, tmp_path, capsys):
    path = make_scenario(duration_s=0.3, state="rest")
    assert main(["run", str(path), "-o", str(tmp_path / "o"), "--json", "--no-plots",
                 "--set", "circuit.pi.u_max_V=0.3"]) == 0
    cap = capsys.readouterr()
    s = json.loads(cap.out)
    assert s["status"] == "saturated"
    assert "saturated" in cap.err


def test_a_loop_that_never_starts_is_reported(make_scenario, tmp_path, capsys):
    # an inverted drive amplifier turns the positive feedback negative: no oscillation
    path = make_scenario(duration_s=0.2, state="rest")
    assert main(["run", str(path), "-o", str(tmp_path / "o"), "--json", "--no-plots",
                 "--set", "circuit.drive_amp.gain=-2.0"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["status"] == "no_oscillation"


@pytest.mark.parametrize("scenario, overrides, expected", [
    ("startup", ["scenario.duration_s=0.05"], "startup: drive loop start-up"),
    ("oven_004", ["scenario.duration_s=120", "scenario.output_rate_Hz=1"],
     "oven_004: drive amplitude loop over 120 s (started at its steady state)"),
])
def test_the_drive_loop_plot_is_titled_for_what_it_shows(tmp_path, monkeypatch, capsys, scenario, overrides,
                                                         expected):
    import fmvmg_sim.plots as plots
    titles = {}
    real = plots.save_figure

    def spy(fig, path):
        titles[Path(path).name] = fig.axes[0].get_title()
        real(fig, path)

    monkeypatch.setattr(plots, "save_figure", spy)
    sets = [a for o in overrides for a in ("--set", o)]
    assert main(["run", scenario, *sets, "-o", str(tmp_path / "o"), "--no-progress"]) == 0
    assert titles["startup.png"] == expected


def test_the_drive_loop_title_gives_long_runs_in_hours():
    from fmvmg_sim.plots import drive_loop_title
    assert drive_loop_title("oven_004", "steady", 47250.0) == \
        "oven_004: drive amplitude loop over 13.1 h (started at its steady state)"
    assert drive_loop_title("startup", "rest", 1.5) == "startup: drive loop start-up"
