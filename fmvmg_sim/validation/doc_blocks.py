"""Generated blocks inside hand-written documentation pages.

A page keeps its prose; the tables a script measures sit between two marker lines::

    <!-- generated: real-records (python benchmarks/real_records.py --docs ...); do not edit -->
    | ... the table ... |
    <!-- end generated: real-records -->

:func:`replace_block` swaps what lies between the markers of one block and writes the page
whole (atomically), so a page never holds a hand-edited or half-written table.
"""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import InputError
from ..record import atomic_write_text


def _pattern(name: str) -> re.Pattern:
    return re.compile(r"(<!-- generated: " + re.escape(name) + r"\b[^\n]*-->\n)(.*?)(<!-- end generated: "
                      + re.escape(name) + r" -->)", re.S)


def read_block(path: str | Path, name: str) -> str:
    """The text between the markers of block ``name`` in a page.

    Parameters
    ----------
    path : path-like
        The page.
    name : str
        The block's name, as in its markers.

    Returns
    -------
    str

    Raises
    ------
    InputError
        When the page has no such block.
    """
    m = _pattern(name).search(Path(path).read_text(encoding="utf-8"))
    if m is None:
        raise InputError(f"no generated block {name!r} (marker lines '<!-- generated: {name} ... -->' and "
                         f"'<!-- end generated: {name} -->')", str(path))
    return m.group(2)


def replace_block(path: str | Path, name: str, text: str) -> None:
    """Replace what lies between the markers of block ``name`` with ``text``, writing the page whole.

    Parameters
    ----------
    path : path-like
        The page (markdown).
    name : str
        The block's name.
    text : str
        The new content (a trailing newline is added when missing).

    Raises
    ------
    InputError
        When the page has no such block (nothing is written).
    """
    read_block(path, name)  # the block must be there
    page = Path(path).read_text(encoding="utf-8")
    body = text if text.endswith("\n") else text + "\n"
    atomic_write_text(path, _pattern(name).sub(lambda m: m.group(1) + body + m.group(3), page, count=1))
