"""Analyses of records: Allan deviation and the IEEE 952 noise terms.

Modules
-------
allan      : overlapping Allan deviation, confidence intervals, ARW / bias instability / RRW
allan_plot : the log-log PNG of an :class:`~fmvmg_sim.analysis.allan.AllanResult`
series     : a uniform, gap-free sample series from a record (uneven steps, gaps, NaNs)

The names below are imported on first use, so that importing one sub-module (``series``) does not
import allantools.
"""

from __future__ import annotations

import importlib

_WHERE = {"AllanResult": "allan", "allan_deviation": "allan", "oadev_numpy": "allan",
          "Series": "series", "series_from_record": "series"}

__all__ = list(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
