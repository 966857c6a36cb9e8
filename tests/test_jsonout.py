"""The one JSON sanitiser: what numpy and the non-finite floats become, read back by a strict parser."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fmvmg_sim.jsonout import strict


def _strict_loads(text: str):
    def refuse(name):
        raise ValueError(f"non-standard JSON constant {name}")
    return json.loads(text, parse_constant=refuse)


def test_numpy_and_non_finite_values_become_strict_json():
    obj = {"a": np.float64(1.5), "b": np.int32(-3), "c": np.bool_(True), "d": float("nan"),
           "e": np.array([1.0, np.inf, -2.0]), "f": (np.float32(0.25), None, "x"), "g": np.array(7.0),
           "h": [[np.nan, 2], {"i": -np.inf}], 3: "int key"}
    text = json.dumps(strict(obj), allow_nan=False)
    back = _strict_loads(text)
    assert back == {"a": 1.5, "b": -3, "c": True, "d": None, "e": [1.0, None, -2.0], "f": [0.25, None, "x"],
                    "g": 7.0, "h": [[None, 2], {"i": None}], "3": "int key"}
    assert type(back["b"]) is int and type(back["c"]) is bool


def test_private_keys_dropped_on_request_only():
    obj = {"_cache": 1, "kept": {"_inner": 2, "x": 3}}
    assert strict(obj, drop_private=True) == {"kept": {"x": 3}}
    assert strict(obj) == obj


def test_input_left_unchanged():
    obj = {"x": [np.nan, 1.0]}
    strict(obj)
    assert np.isnan(obj["x"][0])


@pytest.mark.parametrize("value", [np.float64(np.nan), np.float32(np.inf), float("-inf")])
def test_each_non_finite_scalar_is_null(value):
    assert strict(value) is None
