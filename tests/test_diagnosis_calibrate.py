"""Calibration (fmvmg_sim.diagnosis.calibrate): the Q law's other start within the knobs' bounds, and what releasing
a bound gains."""

from types import SimpleNamespace

import numpy as np
import pytest

from fmvmg_sim.diagnosis.calibrate import (FREE_MOLECULAR_EXPONENT, Calibration, law_starts, release_gains,
                                           resolution)
from fmvmg_sim.diagnosis.fitting import Fitter, Lin
from fmvmg_sim.diagnosis.parameters import KnobSet, apply_nominal
from fmvmg_sim.scenario import load_scenario
from tests.test_diagnosis_helpers import NOMINAL

T_C = np.linspace(-40.0, 70.0, 23)


def _q_law(device) -> np.ndarray:
    """ln(Q(T)/Q(25 C)) of the drive mode."""
    q = np.array([device.at(float(t)).values["mechanics"]["q_drive"] for t in T_C])
    return np.log(q / device.at(25.0).values["mechanics"]["q_drive"])


def test_the_other_start_is_the_free_molecular_gas_law():
    """From the other start the drive Q follows the free-molecular law T^-1/2 to 0.25 % from -40 to 70 C (its
    thermoelastic and anchor losses a tenth of the file's), where the device file's mix is 18 % off it; and beyond
    a quadratic in T (what the curvature and the effort's gain drift can take) to 20 ppm, where the file's mix
    leaves 120 ppm."""
    dev = load_scenario(NOMINAL).device_nominal
    starts = law_starts(KnobSet.of(dev), dev)
    assert len(starts) == 1
    start = starts[0]
    assert dev.values["thermal"]["q_gas_exponent"] + start["q_gas_exponent"] == FREE_MOLECULAR_EXPONENT
    gas = -0.5 * np.log((T_C + 273.15) / 298.15)
    A = np.c_[np.ones_like(T_C), T_C - 25.0, (T_C - 25.0) ** 2]
    off = {}
    for name, theta in (("file", {}), ("start", start)):
        r = _q_law(apply_nominal(dev, theta)) - gas
        off[name] = (np.abs(r).max(), np.abs(r - A @ np.linalg.lstsq(A, r, rcond=None)[0]).max())
    assert off["start"][0] < 2.5e-3 and off["file"][0] > 0.15
    assert off["start"][1] < 2e-5 and off["file"][1] > 1e-4


def test_the_start_stays_within_the_bounds_and_needs_the_solid_damping_knob():
    """A device whose gas exponent tolerance cannot reach 1/2 starts at its bound; a device without the
    solid-damping knob has no other start."""
    dev = load_scenario(NOMINAL).device_nominal
    tight = dev.with_overrides({"tolerance": {"q_gas_exponent": 0.2}}, "test")
    ks = KnobSet.of(tight)
    start = law_starts(ks, tight)[0]
    j = ks.names.index("q_gas_exponent")
    assert start["q_gas_exponent"] == ks.lo[j] == pytest.approx(-0.3)
    assert start["q_solid_damping_rel"] == ks.lo[ks.names.index("q_solid_damping_rel")]
    plain = dev.with_overrides({"tolerance": {"q_solid_damping_rel": 0.0}}, "test")
    assert law_starts(KnobSet.of(plain), plain) == []


def _lin_problem(cols: np.ndarray, y: np.ndarray, x0: np.ndarray, tol: float = 1.0):
    """A linear calibration problem on one channel: a fitter-like object (unit block sigma) and its Lin at ``x0``."""
    n, k = cols.shape
    fit = SimpleNamespace(S=np.ones((n, 1)), Y=y[:, None], present=np.ones(1, bool),
                          knobs=SimpleNamespace(tolerance=np.full(k, tol)))
    fit.solve = Fitter.solve.__get__(fit)
    lin = Lin(y0=(cols @ x0)[:, None], cols=cols[:, None, :], names=[f"k{i}" for i in range(k)], x0=x0.astype(float),
              prior_sd=np.full(k, tol), lo=np.full(k, -1.5 * tol), hi=np.full(k, 1.5 * tol))
    return fit, lin


def test_release_gain_tells_a_bound_the_record_asks_for_from_a_flat_valley():
    """A knob the data push to 3 tolerances gains ~ n (1.5 tol)^2 var(col) when released; two collinear knobs whose
    sum the data fix, one of them left at its bound, gain nothing: the objective is flat along the valley but for
    the prior, whose optimum lies inside the bounds (far below the calibration's resolution on a record whose misfit
    is 4000): that bound is a flat valley's, not asked for by the record."""
    rng = np.random.default_rng(3)
    n = 4000
    noise = rng.normal(size=n)
    a, b = rng.normal(size=n), rng.normal(size=n)
    fit, lin = _lin_problem(np.c_[a, b], 3.0 * a + noise, np.array([1.5, 0.0]))
    gain = release_gains(fit, lin, np.ones(n, bool), ["k0"])["k0"]
    assert gain == pytest.approx(np.sum((1.5 * a) ** 2) - (3.0 ** 2 - 1.5 ** 2), rel=0.05)
    fit, lin = _lin_problem(np.c_[a, a], 2.0 * a + noise, np.array([1.5, 0.5]))
    rows = np.ones(n, bool)
    gain = release_gains(fit, lin, rows, ["k0"])["k0"]
    sol = fit.solve(lin, rows)
    objective = sol.cost + float(sol.x @ sol.x)
    assert objective == pytest.approx(n, rel=0.1)
    # the linearised optimum splits the sum evenly (the prior's (1, 1)), inside the bound: the calibration stopped on
    # the flat valley short of it, and releasing the bound gains nothing
    assert np.allclose(sol.x, [1.0, 1.0], atol=0.01)
    assert gain == pytest.approx(0.0, abs=1e-6) and gain < resolution(objective)
    cal = Calibration(theta={"k0": 1.5, "k1": 0.5}, sd={}, identifiable={}, correlated=[], lin=lin, base=None,
                      iterations=1, solution=sol, tolerance={"k0": 1.0, "k1": 1.0}, objective=objective,
                      release_gain={"k0": gain})
    assert cal.at_bound == ["k0"] and cal.asked_at_bound == []
    cal.release_gain = {"k0": 10 * resolution(objective)}
    assert cal.asked_at_bound == ["k0"]
