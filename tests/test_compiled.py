"""The compiled roll-out: its noise generator, and the virtual-machine fallback against compiled code."""

import os

import numpy as np
import pytest
from scipy import stats

from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.carrier.step import CARRIER_MODEL
from fmvmg_sim.compiled import load_rollout
from fmvmg_sim.scenario import load_scenario


@pytest.fixture(scope="module")
def roll():
    r = load_rollout(CARRIER_MODEL, log=lambda m: None)
    if not r.compiled:
        pytest.skip("no C compiler on this machine")
    return r


def test_compiled_normals_are_standard_normal(roll):
    x = roll.normals(12345, 2_000_000)
    assert abs(x.mean()) < 3e-3
    assert x.var() == pytest.approx(1.0, abs=4e-3)
    assert stats.kurtosis(x, fisher=False) == pytest.approx(3.0, abs=0.03)
    assert np.mean(np.abs(x) > 3.0) == pytest.approx(2 * stats.norm.sf(3.0), rel=0.1)
    assert np.mean(np.abs(x) > 4.0) == pytest.approx(2 * stats.norm.sf(4.0), rel=0.35)  # the ziggurat's tail
    assert stats.kstest(x[:200_000], "norm").pvalue > 1e-3
    # no serial correlation
    assert abs(np.corrcoef(x[:-1], x[1:])[0, 1]) < 3e-3
    assert np.array_equal(roll.normals(7, 1000), roll.normals(7, 1000))
    assert not np.array_equal(roll.normals(7, 1000), roll.normals(8, 1000))


def test_virtual_machine_fallback_matches_compiled_code(make_scenario, monkeypatch):
    path = make_scenario(duration_s=0.004, output_rate_Hz=2000.0, state="rest")
    compiled = run_carrier(load_scenario(path), progress=False)
    import fmvmg_sim.compiled as comp
    monkeypatch.setenv("FMVMG_NO_COMPILE", "1")
    monkeypatch.setattr(comp, "_WARNED", False)
    msgs = []
    vm = run_carrier(load_scenario(path), progress=False, log=msgs.append)
    assert not vm.info["compiled"] and compiled.info["compiled"]
    assert any("virtual machine" in m for m in msgs)
    for k in ("drive_amplitude_V", "agc_effort_V", "quadrature_V"):
        assert np.allclose(vm[k], compiled[k], rtol=1e-9, atol=1e-12), k
