"""Where the shipped scenarios and devices are, and how a scenario or device name is resolved.

The scenarios and devices travel with the package as the regular package ``fmvmg_sim.scenarios``
(the top-level ``scenarios/`` folder of the source tree, mapped in ``pyproject.toml``). They are
found with :func:`importlib.resources.files`, as its documentation prescribes, so an installed
wheel, an editable install and a source checkout all give the same files.

Resolution rules (the same for every command):

* a scenario argument that names an existing file is that file; otherwise a shipped scenario of
  that name (``startup`` or ``startup.toml``);
* a scenario's ``device_file`` is looked up relative to the scenario's folder first, then among
  the shipped files (``devices/fmvmg_a.toml``, ``fmvmg_a.toml`` or plain ``fmvmg_a``), so a
  scenario copied out of the source tree still finds the shipped devices.
"""

from __future__ import annotations

import atexit
import contextlib
from functools import lru_cache
from importlib import resources
from pathlib import Path

#: The package that holds the shipped scenarios (``devices/`` inside it).
SCENARIOS_PACKAGE = "fmvmg_sim.scenarios"
#: Sub-folder of the shipped scenarios holding the device files.
DEVICES_SUBDIR = "devices"

_keep_open = contextlib.ExitStack()
atexit.register(_keep_open.close)


@lru_cache(maxsize=1)
def scenarios_dir() -> Path:
    """The folder holding the shipped scenario files (``devices/`` inside it).

    Returns
    -------
    Path
        A real directory. For an installed or editable package it is the package data of
        ``fmvmg_sim.scenarios``; when the package is imported from a bare source tree (no install,
        so the ``scenarios`` mapping does not exist) it is the tree's top-level ``scenarios/``.
    """
    try:
        ref = resources.files(SCENARIOS_PACKAGE)
    except ModuleNotFoundError:
        return Path(__file__).resolve().parent.parent / "scenarios"
    if isinstance(ref, Path):
        return ref
    # Not on a plain file system (e.g. a zip import): as_file gives a real copy that lives
    # until the interpreter exits.
    return Path(_keep_open.enter_context(resources.as_file(ref)))


def devices_dir() -> Path:
    """The folder holding the shipped device files.

    Returns
    -------
    Path
    """
    return scenarios_dir() / DEVICES_SUBDIR


def shipped_scenarios() -> list[str]:
    """Names of the shipped scenarios (file stems), sorted.

    Returns
    -------
    list of str
    """
    return sorted(p.stem for p in scenarios_dir().glob("*.toml"))


def shipped_devices() -> list[str]:
    """Names of the shipped device files (file stems), sorted.

    Returns
    -------
    list of str
    """
    return sorted(p.stem for p in devices_dir().glob("*.toml"))


def _with_toml(name: str) -> str:
    return name if name.endswith(".toml") else f"{name}.toml"


def resolve_scenario(path: str | Path) -> Path:
    """The scenario file a command argument names.

    Parameters
    ----------
    path : str or Path
        A file path, or the name of a shipped scenario (``startup`` or ``startup.toml``).

    Returns
    -------
    Path
        ``path`` itself when it is a file, has a folder part, or no shipped scenario has that name
        (so that the caller reports what is wrong with it); otherwise the shipped scenario, even
        when a folder of that name is in the way (an earlier run's ``-o oven_000``).
    """
    p = Path(path)
    if p.is_file() or p.parent != Path("."):
        return p
    shipped = scenarios_dir() / _with_toml(p.name)
    return shipped if shipped.is_file() else p


def device_candidates(device_file: str, scenario_dir: str | Path | None = None) -> list[Path]:
    """Where a scenario's ``device_file`` may be, in the order they are tried.

    Parameters
    ----------
    device_file : str
        The scenario's ``scenario.device_file``: a path (relative to the scenario's folder or
        absolute), a path relative to the shipped scenarios (``devices/fmvmg_a.toml``) or a
        shipped device name (``fmvmg_a``).
    scenario_dir : str or Path, optional
        The folder of the scenario file.

    Returns
    -------
    list of Path
    """
    d = Path(device_file)
    out = []
    if scenario_dir is not None:
        out.append(Path(scenario_dir) / d)
    elif d.is_absolute():
        out.append(d)
    shipped, devices = scenarios_dir(), devices_dir()
    out += [shipped / d, devices / d.name, devices / _with_toml(d.name)]
    seen, unique = set(), []
    for c in out:
        if c not in seen:
            seen.add(c)
            unique.append(c)
    return unique


def resolve_device(device_file: str, scenario_dir: str | Path | None = None) -> Path | None:
    """The device file a scenario's ``device_file`` names, or None when there is none.

    Parameters
    ----------
    device_file : str
        See :func:`device_candidates`.
    scenario_dir : str or Path, optional
        The folder of the scenario file.

    Returns
    -------
    Path or None
    """
    return next((c for c in device_candidates(device_file, scenario_dir) if c.is_file()), None)
