"""The Python entry points, for notebooks and scripts: the same jobs as the ``fmvmg`` commands.

Every name here is also available as ``fmvmg_sim.<name>`` (imported on first use, so that
``import fmvmg_sim`` stays fast)::

    import fmvmg_sim as fm
    result = fm.simulate("startup", overrides=["scenario.duration_s=0.3"])
    record = result.to_record()                 # the record format of docs/formats.md
    fm.allan(record).plot("allan.png")

Bad input raises :class:`fmvmg_sim.errors.InputError`, whose message names the file, key or line,
as the commands' exit code 2 does.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from .errors import InputError
from .record import Record, read_record, write_record
from .scenario import Scenario, load_scenario

__all__ = ["load_scenario", "simulate", "read_record", "write_record", "allan", "compensator",
           "compensators", "diagnose", "tune", "InputError", "Record", "Scenario"]


def simulate(scenario: str | os.PathLike | Scenario, overrides: Sequence[str] | None = None,
             seed: int | None = None, fidelity: str | None = None, progress: bool = False):
    """Simulate a scenario, as ``fmvmg run`` does (without writing files).

    Parameters
    ----------
    scenario : str, path-like or Scenario
        A scenario file, the name of a shipped scenario (``"startup"``, ``"oven_004"``, ...), or a
        scenario already loaded with :func:`load_scenario`.
    overrides : sequence of str, optional
        ``KEY=VALUE`` strings, as ``--set`` (only with a file or name).
    seed : int, optional
        Overrides ``scenario.seed``.
    fidelity : {"carrier", "envelope", "auto"}, optional
        The engine (default: the scenario's).
    progress : bool, optional
        A progress bar on stderr.

    Returns
    -------
    SimResult
        Labelled channels (``result["rate_dps"]``, ``result.time_s``), ``result.summary`` (what
        ``summary.json`` holds) and ``result.to_record()``.

    Raises
    ------
    InputError
        A bad scenario or override, or a record too large for the memory available.
    """
    if isinstance(scenario, Scenario):
        if overrides or seed is not None or fidelity is not None:
            raise InputError("overrides, seed and fidelity apply when loading; pass a file or a name",
                             "simulate")
        scn = scenario
    else:
        scn = load_scenario(scenario, list(overrides or []), seed=seed, fidelity=fidelity)
    from .runner import run_scenario
    res, summary = run_scenario(scn, progress=progress)
    res.summary = summary
    return res


def allan(data, column: str = "rate_dps", fs_Hz: float | None = None, resample: bool = False,
          taus: str = "octave"):
    """Overlapping Allan deviation with ARW, bias instability and RRW, as ``fmvmg allan`` does.

    Parameters
    ----------
    data : Record, SimResult, path-like or array_like
        A record (or a file holding one, or a simulation result), or a plain rate series
        (then ``fs_Hz`` is needed).
    column : str, optional
        The record column to analyse (default ``rate_dps``; the deg-based terms assume deg/s).
    fs_Hz : float, optional
        Sample rate of a plain series.
    resample : bool, optional
        Interpolate an uneven or gapped record onto a uniform grid.
    taus : {"octave", "dense"}, optional
        Octave taus, or about 10 log-spaced taus per decade.

    Returns
    -------
    AllanResult
        ``taus_s``, ``adev``, ``arw_deg_per_sqrt_h``, ``bias_instability_deg_per_h``, ... and
        ``.plot(path)``, ``.to_dict()``.

    Raises
    ------
    InputError
        A record without the column, uneven steps without ``resample``, or a series too short.
    """
    import numpy as np

    from .analysis.allan import allan_deviation
    from .analysis.series import series_from_record
    if hasattr(data, "to_record"):
        data = data.to_record()
    if isinstance(data, (str, os.PathLike)):
        data = read_record(data, required=("time_s", column))
    if isinstance(data, Record):
        series = series_from_record(data, column, resample=resample)
        res = allan_deviation(series.values, series.fs_Hz, taus=taus, unit=series.unit, column=column)
        res.notes[:0] = series.notes
        return res
    if fs_Hz is None:
        raise InputError("a plain series needs its sample rate", "fs_Hz")
    return allan_deviation(np.asarray(data, dtype=float), fs_Hz, taus=taus)


def compensators() -> list[str]:
    """The names of the drift-compensation methods (``fmvmg compensate --method``).

    Returns
    -------
    list of str
    """
    from .compensation.base import METHODS, _load_builtin_methods
    _load_builtin_methods()
    return sorted(METHODS)


def compensator(method: str, **params):
    """A drift compensator, a scikit-learn-style estimator on records.

    Parameters
    ----------
    method : str
        One of :func:`compensators` (``"poly-baseline"``, ``"emd-rbf-ga-kf"``, ``"vmd-wflp-cssvr"``, ...).
    **params
        The method's hyper-parameters (see its ``get_params()``).

    Returns
    -------
    Compensator
        Unfitted: ``comp.fit(train_record)``, then ``comp.transform(record)`` gives the compensated
        record (``rate_dps`` compensated, the input's in ``rate_raw_dps``) and
        ``comp.compensate_rate_dps(record)`` the compensated rate alone (deg/s);
        ``comp.fit_transform(record)`` fits and compensates in-sample.

    Raises
    ------
    InputError
        An unknown method.
    """
    from .compensation import get_method
    return get_method(method)(**params)


def diagnose(record: str | os.PathLike, scenario: str | os.PathLike = "nominal_a", n_null: int | None = None,
             seed: int = 0, progress: bool = False) -> dict:
    """The sim-to-real gap report of a record, as ``fmvmg diagnose`` gives.

    Parameters
    ----------
    record : path-like
        A record file (oven or rate-table run; rate and temperature required).
    scenario : str or path-like, optional
        The nominal scenario (device, circuit, noise); default the shipped ``nominal_a``.
    n_null : int, optional
        Null re-simulations (default as the command).
    seed : int, optional
        Seed of the null re-simulations.
    progress : bool, optional
        Progress bars on stderr.

    Returns
    -------
    dict
        The report of docs/formats.md (``verdict``, ``accepted``, ``ranked``, ``localization``, ...).

    Raises
    ------
    InputError
        A bad record or scenario.
    """
    from .diagnosis.pipeline import N_NULL
    from .diagnosis.pipeline import diagnose as _diagnose
    from .diagnosis.report import json_report
    from .paths import resolve_scenario
    rep = _diagnose(record, resolve_scenario(scenario), n_null=n_null or N_NULL, seed=seed, progress=progress,
                    log=None if progress else (lambda m: None))
    return json_report(rep)


def tune(scenario: str | os.PathLike | Scenario = "startup", temperatures_C: Sequence[float] = (-40.0, 25.0, 85.0),
         gains: tuple[float, float] | None = None, simulate: bool = True):
    """PI gains of the drive amplitude loop, robust over temperature, as ``fmvmg tune`` gives.

    Parameters
    ----------
    scenario : str, path-like or Scenario, optional
        Whose device (and circuit overrides) to tune; default the shipped ``startup``.
    temperatures_C : sequence of float, optional
        Temperatures of the table and of the simulation checks.
    gains : tuple of float, optional
        (Kp, Ki in 1/s) to check instead of running the robust optimisation.
    simulate : bool, optional
        Check the gains with the carrier engine (a set-point step and a start-up).

    Returns
    -------
    TuneReport
        ``gains``, ``metrics`` (margins, settling per temperature), ``steps``, ``startups`` and
        ``as_dict()``.
    """
    from .tuning.report import build_report
    scn = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    return build_report(scn.device, temperatures_C, given=gains, simulate=simulate)
