"""Entry point of the ``fmvmg`` console script.

Exit codes (CONTRACTS.md section 1): 0 success, 2 bad input (one line naming the
file, key or line), 1 internal failure. Set ``FMVMG_DEBUG=1`` to see tracebacks.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
import warnings

from ..errors import InputError

#: Sub-command modules, in the order ``--help`` lists them.
SUBCOMMANDS = ("run", "allan", "tune", "compensate", "compensate_eval", "diagnose", "diagnose_benchmark", "import_bmi270")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # argparse's own usage errors are bad input too
        self.print_usage(sys.stderr)
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    """The ``fmvmg`` parser with every available sub-command registered."""
    parser = _Parser(prog="fmvmg", description="MEMS vibratory gyroscope drive/sense co-simulator")
    from .. import __version__
    parser.add_argument("--version", action="version", version=f"fmvmg-sim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in SUBCOMMANDS:
        try:
            mod = importlib.import_module(f".{name}", __package__)
        except ModuleNotFoundError as exc:
            if exc.name and exc.name.endswith(f"cli.{name}"):
                continue  # sub-command not built yet
            raise
        mod.register(sub)
    return parser


def _showwarning(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(f"fmvmg: warning: {message}\n")


def main(argv: list[str] | None = None) -> int:
    """Run ``fmvmg`` with ``argv``; returns the exit code."""
    parser = build_parser()
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
            traceback.print_exc()
        sys.stderr.write(f"fmvmg: internal error: {type(exc).__name__}: {exc} "
                         "(set FMVMG_DEBUG=1 for a traceback)\n")
        return 1


def entry() -> None:
    """Console-script entry point."""
    raise SystemExit(main())


if __name__ == "__main__":
    entry()
