"""Entry point of the ``fmvmg`` console script.

Exit codes (docs/formats.md section 1): 0 success, 2 bad input (one line naming the
file, key or line), 1 internal failure. Set ``FMVMG_DEBUG=1`` to see tracebacks.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings

from ..errors import InputError

#: Sub-commands in the order ``--help`` lists them: command -> (module, one-line help). Only the module
#: of the command being run is imported, so ``fmvmg --help`` imports none of the scientific stack.
#: ``tests/test_cli_main.py`` checks each line against the help its module registers.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "run": ("run", "simulate a scenario"),
    "allan": ("allan", "Allan deviation with ARW, bias instability and RRW"),
    "tune": ("tune", "PI gains of the drive amplitude loop (robust over temperature)"),
    "compensate": ("compensate", "temperature-drift compensation of a record"),
    "compensate-eval": ("compensate_eval", "honest held-out evaluation of drift compensators"),
    "diagnose": ("diagnose", "sim-to-real gap diagnosis of a record"),
    "diagnose-benchmark": ("diagnose_benchmark", "score the diagnosis on labelled simulated cases"),
    "diagnose-independent": ("diagnose_independent", "score the diagnosis on labelled records made elsewhere"),
    "population": ("population", "population study: yield over the device's tolerances"),
    "import-bmi270": ("import_bmi270", "convert a BMI270 serial log into a record"),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # argparse's own usage errors are bad input too
        self.print_usage(sys.stderr)
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(2)


def _requested(argv: list[str]) -> str | None:
    """The sub-command named on the command line (the first word that is not an option)."""
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The ``fmvmg`` parser.

    Parameters
    ----------
    argv : list of str, optional
        The command line to be parsed. Only the sub-command it names is registered in full
        (its module imported); the others appear in ``--help`` with their one-line help. Without
        ``argv`` every sub-command is registered in full.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = _Parser(prog="fmvmg", description="MEMS vibratory gyroscope drive/sense co-simulator")
    from .. import __version__
    parser.add_argument("--version", action="version", version=f"fmvmg-sim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    wanted = None if argv is None else _requested(argv)
    for command, (module, help_text) in SUBCOMMANDS.items():
        if argv is None or command == wanted:
            importlib.import_module(f".{module}", __package__).register(sub)
        else:
            sub.add_parser(command, help=help_text)
    return parser


def _showwarning(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(f"fmvmg: warning: {message}\n")


def main(argv: list[str] | None = None) -> int:
    """Run ``fmvmg`` with ``argv``; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    warnings.showwarning = _showwarning
    try:
        rc = args.func(args)
        return int(rc or 0)
    except InputError as exc:
        sys.stderr.write(f"fmvmg: error: {exc}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("fmvmg: interrupted\n")
        return 130
    except Exception as exc:  # internal failure
        if os.environ.get("FMVMG_DEBUG"):
            import traceback
            traceback.print_exc()
        sys.stderr.write(f"fmvmg: internal error: {type(exc).__name__}: {exc} "
                         "(set FMVMG_DEBUG=1 for a traceback)\n")
        return 1


def entry() -> None:
    """Console-script entry point."""
    raise SystemExit(main())


if __name__ == "__main__":
    entry()
