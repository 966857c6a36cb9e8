"""A small schema validator: every key known, every value of the right type and range.

Errors name the key path (``circuit.pi.kp``) and the file, and suggest the nearest
known key for a misspelt or wrong-unit name (``duration_min`` -> ``duration_s``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .errors import InputError
from .tomlio import suggest


@dataclass(frozen=True)
class Num:
    """A real number in [lo, hi] (None = unbounded); ``positive`` excludes zero.

    Parameters
    ----------
    lo, hi : float or None
        Inclusive bounds.
    positive : bool
        Require > 0.
    integer : bool
        Require an integer value.
    allow : tuple of str
        Strings also accepted (e.g. ``("auto",)``).
    """

    lo: float | None = None
    hi: float | None = None
    positive: bool = False
    integer: bool = False
    allow: tuple = ()

    def check(self, value: Any, where: str) -> Any:
        """Validate ``value``; return it (as float or int).

        Parameters
        ----------
        value : object
        where : str
            Key path for messages.

        Returns
        -------
        float or int or str
        """
        if isinstance(value, str) and value in self.allow:
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            extra = f" or one of {list(self.allow)}" if self.allow else ""
            hint = ""
            if isinstance(value, str) and any(c.isalpha() for c in value):
                hint = " (units go in the key name, e.g. duration_s = 600, not '10 min')"
            raise InputError(f"expected a number{extra}, got {value!r}{hint}", where)
        v = float(value)
        if not math.isfinite(v):
            raise InputError(f"expected a finite number, got {value!r}", where)
        if self.integer and v != int(v):
            raise InputError(f"expected an integer, got {value!r}", where)
        if self.positive and v <= 0:
            raise InputError(f"must be > 0, got {value!r}", where)
        if self.lo is not None and v < self.lo:
            raise InputError(f"must be >= {self.lo}, got {value!r}", where)
        if self.hi is not None and v > self.hi:
            raise InputError(f"must be <= {self.hi}, got {value!r}", where)
        return int(v) if self.integer else v


@dataclass(frozen=True)
class Choice:
    """One of a fixed set of strings.

    Parameters
    ----------
    options : tuple of str
    """

    options: tuple

    def check(self, value: Any, where: str) -> Any:
        """Validate ``value``.

        Parameters
        ----------
        value : object
        where : str

        Returns
        -------
        str
        """
        if value not in self.options:
            raise InputError(f"expected one of {list(self.options)}, got {value!r}", where)
        return value


@dataclass(frozen=True)
class Bool:
    """A boolean."""

    def check(self, value: Any, where: str) -> Any:
        """Validate ``value``.

        Parameters
        ----------
        value : object
        where : str

        Returns
        -------
        bool
        """
        if not isinstance(value, bool):
            raise InputError(f"expected true or false, got {value!r}", where)
        return value


@dataclass(frozen=True)
class Text:
    """Any string."""

    def check(self, value: Any, where: str) -> Any:
        """Validate ``value``.

        Parameters
        ----------
        value : object
        where : str

        Returns
        -------
        str
        """
        if not isinstance(value, str):
            raise InputError(f"expected a string, got {value!r}", where)
        return value


def validate_tree(tree: dict, schema: dict, file: str, prefix: str = "", sourced: bool = False) -> dict:
    """Check a nested dict against a nested schema and return plain values.

    Parameters
    ----------
    tree : dict
        Parsed TOML.
    schema : dict
        Same nesting; leaves are ``Num``/``Choice``/``Bool``/``Text`` or a dict. A key
        ``"*"`` in a schema table accepts any sub-key with the given spec.
    file : str
        File name for messages.
    prefix : str, optional
        Key path of ``tree``.
    sourced : bool, optional
        Leaves must be ``{ value = ..., source = "..." }`` tables (device files).

    Returns
    -------
    dict
        The values, with ``{value, source}`` tables reduced to their value.

    Raises
    ------
    InputError
        Unknown key, wrong type, out-of-range value or a missing source.
    """
    out: dict = {}
    if not isinstance(tree, dict):
        raise InputError(f"expected a table, got {tree!r}", f"{file}: {prefix.rstrip('.')}")
    for key, value in tree.items():
        path = f"{prefix}{key}"
        spec = schema.get(key, schema.get("*"))
        if spec is None:
            raise InputError(f"unknown key{suggest(key, schema)}; known keys here: {sorted(schema)}",
                             f"{file}: {path}")
        if isinstance(spec, dict):
            out[key] = validate_tree(value, spec, file, path + ".", sourced)
            continue
        if sourced and not (isinstance(spec, Text) and isinstance(value, str)):
            if not (isinstance(value, dict) and "value" in value):
                raise InputError("expected { value = ..., source = \"[S|D|E] ...\" }", f"{file}: {path}")
            extra = set(value) - {"value", "source"}
            if extra:
                raise InputError(f"unknown field(s) {sorted(extra)}", f"{file}: {path}")
            src = value.get("source", "")
            if not (isinstance(src, str) and src.strip()[:3] in ("[S]", "[D]", "[E]")):
                raise InputError("every number needs a source starting with [S], [D] or [E]", f"{file}: {path}.source")
            value = value["value"]
        out[key] = spec.check(value, f"{file}: {path}")
    return out
