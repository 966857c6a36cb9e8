"""fmvmg-sim: co-simulation of a four-mass vibratory MEMS gyroscope's drive loop and sense chain.

The entry points for notebooks and scripts (see ``docs/python_api.md``), each imported on first
use so that ``import fmvmg_sim`` costs nothing::

    import fmvmg_sim as fm
    scn = fm.load_scenario("startup")                 # a file, or a shipped scenario's name
    result = fm.simulate(scn)                         # labelled channels, .summary, .to_record()
    a = fm.allan(result)                              # Allan deviation, ARW, bias instability, RRW
    comp = fm.compensator("poly-baseline").fit(train_record)
    report = fm.diagnose("record.csv", "nominal_a")   # the sim-to-real gap report
    gains = fm.tune("startup")                        # robust PI gains of the amplitude loop

Sub-packages
------------
device, scenario, profiles : what is simulated (data in ``scenarios/``)
diagram                    : the wiring of paper 000's Figure 3 from ``blocks``
carrier, envelope          : the two engines that run the diagram
numerics                   : what both engines use: exact discretisation, flat-vector layouts
analysis, compensation, tuning, diagnosis : what users do with the records
cli                        : the ``fmvmg`` command
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

#: The public entry points: name -> module that defines it (imported on first use).
_ENTRY_POINTS = {
    "load_scenario": "api", "simulate": "api", "read_record": "api", "write_record": "api", "allan": "api",
    "compensator": "api", "compensators": "api", "diagnose": "api", "tune": "api",
    "InputError": "errors", "Record": "record", "Scenario": "scenario", "SimResult": "result",
}

__all__ = ["__version__", *_ENTRY_POINTS]


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        value = getattr(importlib.import_module(f".{_ENTRY_POINTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
