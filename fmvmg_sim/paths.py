"""Where the shipped scenarios and devices are: the source checkout's ``scenarios/``, or the installed copy."""

from __future__ import annotations

from pathlib import Path


def scenarios_dir() -> Path:
    """The folder holding the shipped scenario files (``devices/`` inside it).

    A source checkout's top-level ``scenarios/`` wins; otherwise the copy installed as package
    data of ``fmvmg_sim.scenarios``.

    Returns
    -------
    Path
    """
    source = Path(__file__).resolve().parent.parent / "scenarios"
    if (source / "devices").is_dir():
        return source
    from importlib.resources import files
    return Path(str(files("fmvmg_sim.scenarios")))
