"""Strict JSON for every file and line the product writes: NaN and infinities become null, numpy values Python ones."""

from __future__ import annotations

import math

import numpy as np


def strict(obj, drop_private: bool = False):
    """A copy of ``obj`` that ``json.dumps`` writes as strict JSON.

    Dict keys become strings; tuples and numpy arrays lists; numpy scalars Python numbers and
    booleans; NaN and infinities ``None``. Other objects are returned unchanged.

    Parameters
    ----------
    obj : object
        Nested dicts, lists, tuples, numpy arrays, numbers (numpy scalars included) and strings.
    drop_private : bool, optional
        Leave out the dict entries whose key starts with ``_``.

    Returns
    -------
    object
    """
    if isinstance(obj, dict):
        return {str(k): strict(v, drop_private) for k, v in obj.items()
                if not (drop_private and str(k).startswith("_"))}
    if isinstance(obj, (list, tuple)):
        return [strict(v, drop_private) for v in obj]
    if isinstance(obj, np.ndarray):
        return strict(obj.tolist(), drop_private)
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
