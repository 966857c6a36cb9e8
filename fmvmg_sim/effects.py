"""Unmodelled effects (CONTRACTS.md section 4 vocabulary), switched on in a scenario's ``[effects]`` table.

This module holds the vocabulary and validation; the effect models themselves are
added by the diagnosis work. Until an effect has a model, asking for it is an input
error rather than a silent no-op.
"""

from __future__ import annotations

from .errors import InputError

#: The effect names of CONTRACTS.md section 4.
EFFECT_NAMES = (
    "thermal_lag", "thermal_hysteresis", "temperature_rate", "demod_phase_drift", "quadrature_drift",
    "q_factor_drift", "mode_split_drift", "feedthrough", "duffing", "flicker_noise", "reference_drift",
    "stress_relaxation", "quantization",
)

#: Effects that have a model in the engines, by name -> parameter names.
MODELS: dict[str, tuple[str, ...]] = {}


def validate_effects(table: dict, where: str) -> dict:
    """Check an ``[effects]`` table: known names, known parameters, implemented models.

    Parameters
    ----------
    table : dict
    where : str

    Returns
    -------
    dict
        The validated table.

    Raises
    ------
    InputError
    """
    if not isinstance(table, dict):
        raise InputError("expected a table of effects", where)
    for name, params in table.items():
        if name not in EFFECT_NAMES:
            from .tomlio import suggest
            raise InputError(f"unknown effect{suggest(name, EFFECT_NAMES)}; known: {list(EFFECT_NAMES)}",
                             f"{where}.{name}")
        if name not in MODELS:
            raise InputError("this effect has no simulation model yet", f"{where}.{name}")
        if not isinstance(params, dict):
            raise InputError("expected a table of parameters", f"{where}.{name}")
        unknown = set(params) - set(MODELS[name])
        if unknown:
            raise InputError(f"unknown parameter(s) {sorted(unknown)}; expected {list(MODELS[name])}",
                             f"{where}.{name}")
    return dict(table)
