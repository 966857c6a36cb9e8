"""The options the sub-commands share, declared once: output folder, JSON on stdout, plots, progress, overrides.

Every output-writing sub-command spells its folder ``-o DIR`` (long forms ``--out`` and ``--output``, both kept
because both have been documented), prints one JSON object on stdout with ``--json``, skips its PNG plots with
``--no-plots`` and its progress bars with ``--no-progress``; a scenario-reading one takes ``--set KEY=VALUE``.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_output(p: argparse.ArgumentParser, default: str | None, what: str = "output folder", *,
               metavar: str = "DIR") -> None:
    """The output folder option ``-o/--out/--output`` (``args.out``).

    Parameters
    ----------
    p : argparse.ArgumentParser
    default : str or None
        The folder used without the option (None: the sub-command derives it; say how in ``what``).
    what : str, optional
        Help text.
    metavar : str, optional
    """
    shown = "" if default is None else f" (default {default})"
    p.add_argument("-o", "--out", "--output", dest="out", default=default, metavar=metavar, help=what + shown)


def add_json(p: argparse.ArgumentParser, what: str = "the summary") -> None:
    """``--json``: print ``what`` as one JSON object on stdout and nothing else there (``args.json``).

    Parameters
    ----------
    p : argparse.ArgumentParser
    what : str, optional
    """
    p.add_argument("--json", action="store_true", help=f"print {what} as one JSON object on stdout and nothing else")


def add_no_plots(p: argparse.ArgumentParser) -> None:
    """``--no-plots``: skip the PNG plots (``args.no_plots``).

    Parameters
    ----------
    p : argparse.ArgumentParser
    """
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")


def add_no_progress(p: argparse.ArgumentParser) -> None:
    """``--no-progress``: no progress bars or messages on stderr (``args.no_progress``).

    Parameters
    ----------
    p : argparse.ArgumentParser
    """
    p.add_argument("--no-progress", action="store_true", help="no progress bars or messages on stderr")


def add_overrides(p: argparse.ArgumentParser, example: str = "circuit.pi.kp=100") -> None:
    """``--set KEY=VALUE`` (repeatable): override any scenario value (``args.overrides``).

    Parameters
    ----------
    p : argparse.ArgumentParser
    example : str, optional
        An override shown in the help.
    """
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help=f"override any scenario value, e.g. --set {example} (repeatable)")


def progress(args: argparse.Namespace):
    """The ``progress`` argument of the library calls: False with ``--no-progress``, else None (automatic).

    Parameters
    ----------
    args : argparse.Namespace

    Returns
    -------
    bool or None
    """
    return False if args.no_progress else None


def output_dir(args: argparse.Namespace, default: Path) -> Path:
    """The output folder: ``-o DIR`` if given, else ``default``.

    Parameters
    ----------
    args : argparse.Namespace
    default : Path

    Returns
    -------
    Path
    """
    return Path(args.out) if args.out else Path(default)
