"""Reading TOML files into validated nested dicts, with errors that name the key path."""

from __future__ import annotations

import difflib
import tomllib
from pathlib import Path
from typing import Any

from .errors import InputError


def load_toml(path: str | Path) -> dict:
    """Parse a TOML file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict

    Raises
    ------
    InputError
        When the file is missing or not valid TOML (the parser's line is named).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError("file not found", str(path))
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", str(path)) from None
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text", str(path)) from None


def suggest(key: str, known) -> str:
    """A 'did you mean' hint for an unknown key.

    Parameters
    ----------
    key : str
    known : iterable of str

    Returns
    -------
    str
        ``" (did you mean 'x'?)"`` or an empty string.
    """
    close = difflib.get_close_matches(key, list(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def get_path(tree: dict, dotted: str) -> Any:
    """Value at a dotted key path (``a.b.c``); KeyError if absent.

    Parameters
    ----------
    tree : dict
    dotted : str

    Returns
    -------
    object
    """
    node: Any = tree
    for part in dotted.split("."):
        node = node[part]
    return node


def set_path(tree: dict, dotted: str, value: Any) -> None:
    """Set a value at a dotted key path, creating tables on the way.

    Parameters
    ----------
    tree : dict
    dotted : str
    value : object
    """
    parts = dotted.split(".")
    node = tree
    for part in parts[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise InputError(f"{part!r} is a value, not a table", dotted)
    node[parts[-1]] = value


def parse_override(text: str) -> tuple[str, Any]:
    """Parse a ``KEY=VALUE`` override; VALUE is read as a TOML value (bare words as strings).

    Parameters
    ----------
    text : str

    Returns
    -------
    tuple
        (dotted key, value)

    Raises
    ------
    InputError
        When there is no ``=`` or the key is empty.
    """
    if "=" not in text:
        raise InputError(f"expected KEY=VALUE, got {text!r}", "--set")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key:
        raise InputError(f"empty key in {text!r}", "--set")
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw  # bare word, e.g. fidelity=envelope
    return key, value
