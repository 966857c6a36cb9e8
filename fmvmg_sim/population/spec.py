"""A specification: limits on the figures of merit, read from a TOML file, and the units that meet it.

::

    [spec]
    name = "tactical_oven"
    description = "what the limits are for"

    [limits]
    bias_25C_dps = { max_abs = 2.0 }                 # |bias at 25 C| <= 2 deg/s
    scale_factor_tc_ppm_per_K = { min = -300.0, max = 300.0 }
    arw_deg_per_sqrt_h = { max = 3.0 }

Each key of ``[limits]`` is a figure of merit of :data:`fmvmg_sim.population.figures.FIGURES`, with any of
``min``, ``max`` (inclusive) and ``max_abs`` (``|value| <= max_abs``). A unit meets the spec when every
limited figure is within its limits; a figure the run could not give (NaN) fails its limit, since it was not
shown to meet it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..paths import scenarios_dir
from ..tomlio import load_toml, suggest
from .figures import FIGURES

#: The keys a limit may hold.
LIMIT_KEYS = ("min", "max", "max_abs")


@dataclass(frozen=True)
class Spec:
    """Limits on figures of merit.

    Parameters
    ----------
    name : str
    limits : dict
        ``{figure: {"min"|"max"|"max_abs": float}}``.
    path : str
        The file it was read from.
    """

    name: str
    limits: dict
    path: str = ""

    def passes(self, figures: dict) -> dict:
        """Whether each limited figure of one unit is within its limits.

        Parameters
        ----------
        figures : dict
            ``{figure: value}`` of one unit.

        Returns
        -------
        dict
            ``{figure: bool}`` for each limited figure.
        """
        out = {}
        for name, lim in self.limits.items():
            v = figures.get(name, float("nan"))
            ok = v is not None and math.isfinite(v)
            if ok and "min" in lim:
                ok = v >= lim["min"]
            if ok and "max" in lim:
                ok = v <= lim["max"]
            if ok and "max_abs" in lim:
                ok = abs(v) <= lim["max_abs"]
            out[name] = bool(ok)
        return out

    def pass_table(self, figures: list) -> np.ndarray:
        """Pass (True) or fail of each unit on each limited figure.

        Parameters
        ----------
        figures : list of dict
            One ``{figure: value}`` per unit.

        Returns
        -------
        ndarray of bool, shape (units, limited figures)
            Columns in the order of :attr:`limits`.
        """
        return np.array([[p[n] for n in self.limits] for p in map(self.passes, figures)], dtype=bool).reshape(
            len(figures), len(self.limits))


def default_spec_path() -> Path:
    """The specification shipped for the population scenario.

    Returns
    -------
    Path
    """
    return scenarios_dir() / "specs" / "population_oven.toml"


def load_spec(path: str | Path) -> Spec:
    """Read and check a specification file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Spec

    Raises
    ------
    InputError
        A missing file, bad TOML, an unknown table, figure or limit key, a non-number, ``min > max``, or no
        limit at all (the file and key are named).
    """
    name = str(path)
    tree = load_toml(path)
    for top in tree:
        if top not in ("spec", "limits"):
            raise InputError(f"unknown table{suggest(top, ('spec', 'limits'))}; tables are spec and limits",
                             f"{name}: {top}")
    meta = tree.get("spec", {})
    if not isinstance(meta, dict):
        raise InputError("expected a table", f"{name}: spec")
    for k in meta:
        if k not in ("name", "description"):
            raise InputError(f"unknown key{suggest(k, ('name', 'description'))}", f"{name}: spec.{k}")
    table = tree.get("limits")
    if not isinstance(table, dict) or not table:
        raise InputError("needs a [limits] table with at least one figure of merit "
                         f"(figures: {sorted(FIGURES)})", f"{name}: limits")
    limits = {}
    for fig, lim in table.items():
        where = f"{name}: limits.{fig}"
        if fig not in FIGURES:
            raise InputError(f"unknown figure of merit{suggest(fig, FIGURES)}; figures are {sorted(FIGURES)}", where)
        if not isinstance(lim, dict) or not lim:
            raise InputError(f"expected a table of {list(LIMIT_KEYS)}, e.g. {{ max_abs = 1.0 }}", where)
        checked = {}
        for k, v in lim.items():
            if k not in LIMIT_KEYS:
                raise InputError(f"unknown limit{suggest(k, LIMIT_KEYS)}; limits are {list(LIMIT_KEYS)}",
                                 f"{where}.{k}")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise InputError(f"expected a finite number, got {v!r}", f"{where}.{k}")
            if k == "max_abs" and v < 0:
                raise InputError(f"must be >= 0, got {v!r}", f"{where}.{k}")
            checked[k] = float(v)
        if "min" in checked and "max" in checked and checked["min"] > checked["max"]:
            raise InputError(f"min {checked['min']} is above max {checked['max']}", where)
        limits[fig] = checked
    return Spec(str(meta.get("name", Path(path).stem)), limits, name)
