"""The ``fmvmg`` entry point: every sub-command listed, and ``--help`` fast (no scientific stack imported)."""

import argparse
import importlib
import json
import subprocess
import sys

import pytest

from fmvmg_sim.cli.main import SUBCOMMANDS, build_parser, main

#: Heavy imports that ``fmvmg --help`` and ``import fmvmg_sim`` must not pay for.
HEAVY = ("numpy", "scipy", "allantools", "matplotlib", "casadi", "dask", "sklearn", "control", "emd")


def _help_of(parser: argparse.ArgumentParser) -> dict:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {c.dest: c.help for c in sub._choices_actions}


def test_the_help_table_matches_what_each_module_registers():
    full = _help_of(build_parser())  # every module registered in full
    assert full == {c: h for c, (_, h) in SUBCOMMANDS.items()}
    assert list(full) == list(SUBCOMMANDS)


def test_only_the_requested_sub_command_is_registered_in_full():
    parser = build_parser(["run", "x.toml"])
    args = parser.parse_args(["run", "x.toml", "--seed", "3"])
    assert args.seed == 3 and callable(args.func)
    assert _help_of(parser) == {c: h for c, (_, h) in SUBCOMMANDS.items()}


def _imported_by(code: str) -> set:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys, json\n"
                          "print(json.dumps(sorted(m.split('.')[0] for m in sys.modules)))"],
                         capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_help_imports_none_of_the_scientific_stack():
    code = ("import contextlib, io\nfrom fmvmg_sim.cli.main import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n        main(['--help'])\n    except SystemExit:\n        pass")
    assert not _imported_by(code) & set(HEAVY)


def test_import_fmvmg_sim_imports_none_of_the_scientific_stack():
    assert not _imported_by("import fmvmg_sim") & set(HEAVY)


@pytest.mark.parametrize("command", list(SUBCOMMANDS))
def test_every_sub_command_has_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "usage: fmvmg " + command in capsys.readouterr().out


def test_an_unknown_command_is_bad_input(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate"])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


def test_every_module_of_the_table_exists():
    for module, _ in SUBCOMMANDS.values():
        assert hasattr(importlib.import_module(f"fmvmg_sim.cli.{module}"), "register")
