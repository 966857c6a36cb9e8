"""A population study's output folder: population.json, units.csv (one row per unit) and the plots."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from ..jsonout import strict
from ..record import atomic_write_text
from .figures import FIGURES
from .study import PopulationResult


def units_csv(pop: PopulationResult) -> str:
    """One row per unit: index, status, pass, figures of merit, knob deviations.

    Parameters
    ----------
    pop : PopulationResult

    Returns
    -------
    str
        CSV text.
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["unit", "status", "passed", *FIGURES, *pop.knobs])
    for u, ok in zip(pop.units, pop.passed):
        w.writerow([u["index"], u["status"], int(ok), *(repr(u["figures"][f]) for f in FIGURES),
                    *(repr(u["knobs"][k]) for k in pop.knobs)])
    return buf.getvalue()


def write_report(pop: PopulationResult, folder: str | Path, plots: bool = True) -> dict:
    """Write a population study into ``folder``.

    Parameters
    ----------
    pop : PopulationResult
    folder : str or Path
        An (output) folder.
    plots : bool, optional
        Also ``histograms.png`` and ``drivers.png``.

    Returns
    -------
    dict
        The report (:meth:`PopulationResult.to_dict`), as written to ``population.json``.
    """
    folder = Path(folder)
    rep = strict(pop.to_dict())
    atomic_write_text(folder / "population.json", json.dumps(rep, indent=2) + "\n")
    atomic_write_text(folder / "units.csv", units_csv(pop))
    if plots:
        from .plots import plot_drivers, plot_histograms
        plot_histograms(pop, folder / "histograms.png")
        if pop.spec is not None:
            plot_drivers(pop, folder / "drivers.png", rep.get("drivers"))
    return rep
