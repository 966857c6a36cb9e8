"""Strict JSON for command outputs: NaN and infinities become null, numpy scalars Python numbers."""

from __future__ import annotations

import math


def strict(obj):
    """A copy of ``obj`` that ``json.dumps`` writes as strict JSON.

    Parameters
    ----------
    obj : object
        Nested dicts, lists, tuples, numbers (numpy scalars and arrays included) and strings.

    Returns
    -------
    object
    """
    if isinstance(obj, dict):
        return {k: strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict(v) for v in obj]
    if getattr(obj, "ndim", 0) > 0 and hasattr(obj, "tolist"):  # a numpy array
        return strict(obj.tolist())
    if hasattr(obj, "item") and not isinstance(obj, (str, bytes)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
