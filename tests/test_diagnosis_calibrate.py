"""Calibration starts (fmvmg_sim.diagnosis.calibrate.law_starts): the Q law's other form within the knobs' bounds."""

import numpy as np
import pytest

from fmvmg_sim.diagnosis.calibrate import FREE_MOLECULAR_EXPONENT, law_starts
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
