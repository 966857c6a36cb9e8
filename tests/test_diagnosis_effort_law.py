"""The calibration start from the AGC effort's own law (fmvmg_sim.diagnosis.effort_law)."""

import numpy as np
import pytest

from fmvmg_sim.diagnosis.effort_law import CHANNEL_KNOBS, LAW_KNOBS, drive_damping, fit_effort_law
from fmvmg_sim.diagnosis.parameters import KnobSet, apply_nominal
from fmvmg_sim.scenario import load_scenario
from tests.test_diagnosis_helpers import NOMINAL

#: A unit across its tolerances: less solid damping, a shallower gas law, its own channel.
TRUE = {"q_drive_rel": -0.12, "q_solid_damping_rel": -0.41, "q_gas_exponent": -0.73, "q_curvature_per_K2": 1.5e-7,
        "agc_effort_offset_V": 0.029, "agc_effort_gain_rel": 0.010, "agc_effort_tc_per_K": 2.1e-5}
#: Where a calibration from the nominal unit stops on such a unit: the solid share at nominal, the effort's gain
#: drift at its bound in the law's place.
STUCK = {"q_drive_rel": -0.03, "q_solid_damping_rel": 0.0, "q_gas_exponent": -0.65, "q_curvature_per_K2": -9e-8,
         "agc_effort_offset_V": -0.008, "agc_effort_gain_rel": -0.024, "agc_effort_tc_per_K": -1.5e-4}
SIGMA_V = 5e-6


@pytest.fixture(scope="module")
def device():
    return load_scenario(NOMINAL).device_nominal


def _effort(device, theta, die_C, case_dT, unit):
    return (theta["agc_effort_offset_V"] + (1 + theta["agc_effort_gain_rel"])
            * (1 + theta["agc_effort_tc_per_K"] * case_dT) * unit * drive_damping(device, theta, die_C))


def test_drive_damping_is_the_devices_q_law(device):
    """The start's law is the device's: 1/Q of the drive mode at each temperature, the knobs applied."""
    T = np.linspace(-40.0, 85.0, 11)
    q = np.array([apply_nominal(device, TRUE).at(float(t)).values["mechanics"]["q_drive"] for t in T])
    np.testing.assert_allclose(drive_damping(device, TRUE, T), 1.0 / q, rtol=1e-12)


def test_the_effort_alone_leaves_the_stuck_corner(device):
    """From the corner a calibration stops in, the effort alone is fitted to its noise (reduced chi-square about
    1, where the corner leaves thousands) with the gain drift off its bound, and the recorded curve is the unit's
    to a third of the noise at every block; the knobs themselves trade (level against offset and gain)."""
    rng = np.random.default_rng(3)
    die_C = np.repeat(np.linspace(-40.0, 85.0, 26), 20)
    case_dT = die_C - 25.0 + 0.3
    unit = np.full(die_C.size, 2.0e4)  # about 1 V of effort at Q = 2e4
    clean = _effort(device, TRUE, die_C, case_dT, unit)
    y = clean + SIGMA_V * rng.standard_normal(die_C.size)
    sig = np.full(die_C.size, SIGMA_V)
    chi2 = lambda th: float(np.sum(((y - _effort(device, th, die_C, case_dT, unit)) / SIGMA_V) ** 2))
    assert chi2(STUCK) / die_C.size > 1e3
    fit = fit_effort_law(device, KnobSet.of(device), STUCK, die_C, case_dT, y, sig, unit)
    assert set(fit) == set(LAW_KNOBS + CHANNEL_KNOBS)
    assert chi2(fit) / die_C.size < 1.2
    ks = KnobSet.of(device)
    assert abs(fit["agc_effort_tc_per_K"]) < 0.5 * ks.hi[ks.names.index("agc_effort_tc_per_K")]
    assert np.max(np.abs(_effort(device, fit, die_C, case_dT, unit) - clean)) < SIGMA_V / 3
