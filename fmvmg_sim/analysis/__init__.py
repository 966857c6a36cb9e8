"""Analyses of records: Allan deviation and the IEEE 952 noise terms.

Modules
-------
allan      : overlapping Allan deviation, confidence intervals, ARW / bias instability / RRW
allan_plot : the log-log PNG of an :class:`~fmvmg_sim.analysis.allan.AllanResult`
series     : a uniform, gap-free sample series from a record (uneven steps, gaps, NaNs)
"""

from .allan import AllanResult, allan_deviation, oadev_numpy
from .series import Series, series_from_record

__all__ = ["AllanResult", "allan_deviation", "oadev_numpy", "Series", "series_from_record"]
