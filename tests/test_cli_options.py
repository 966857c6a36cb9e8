"""The options the sub-commands share (fmvmg_sim/cli/options.py): one spelling and one meaning in every command."""

import pytest

from fmvmg_sim.cli.main import build_parser

#: Sub-commands that write an output folder, with the arguments they need besides it.
WRITERS = {
    "run": ["s.toml"],
    "diagnose": ["r.csv", "--scenario", "s.toml"],
    "population": ["s.toml", "--units", "3"],
    "tune": [],
    "diagnose-benchmark": [],
    "diagnose-independent": ["folder"],
    "allan": ["r.csv"],
    "compensate": ["r.csv"],
    "compensate-eval": [],
}


@pytest.mark.parametrize("command", sorted(WRITERS))
@pytest.mark.parametrize("flag", ["-o", "--out", "--output"])
def test_every_writer_takes_its_folder_the_same_way(command, flag):
    argv = [command, *WRITERS[command], flag, "somewhere", "--json"]
    args = build_parser(argv).parse_args(argv)
    assert args.out == "somewhere"
    assert args.json is True


@pytest.mark.parametrize("command", ["run", "diagnose", "population", "tune", "compensate-eval"])
def test_plots_and_progress_switch_off_the_same_way(command):
    argv = [command, *WRITERS[command], "--no-plots", "--no-progress"]
    args = build_parser(argv).parse_args(argv)
    assert (args.no_plots, args.no_progress) == (True, True)
    plain = build_parser([command, *WRITERS[command]]).parse_args([command, *WRITERS[command]])
    assert (plain.no_plots, plain.no_progress) == (False, False)


@pytest.mark.parametrize("command", ["run", "population", "tune"])
def test_overrides_accumulate_in_order(command):
    argv = [command, *WRITERS[command], "--set", "a.b=1", "--set", "c.d=2"]
    assert build_parser(argv).parse_args(argv).overrides == ["a.b=1", "c.d=2"]


def test_fixed_default_folders_are_kept():
    assert build_parser(["tune"]).parse_args(["tune"]).out == "out/tune"
    argv = ["diagnose-independent", "folder"]
    assert build_parser(argv).parse_args(argv).out == "out/diagnose_independent"
    assert build_parser(["run"]).parse_args(["run", "s.toml"]).out is None
