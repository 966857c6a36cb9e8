"""Operating plans: the discretised diagram at one temperature."""

import numpy as np
import pytest

from fmvmg_sim.averaged import steady_state
from fmvmg_sim.carrier.plan import _resonator_direction
from fmvmg_sim.device import load_device
from fmvmg_sim.diagram import build_diagram


@pytest.mark.parametrize("device", ["fmvmg_a", "fmvmg_b"])
@pytest.mark.parametrize("T", [-40.0, 85.0])
def test_rate_and_quadrature_directions_equal_differenced_cores(device, T):
    """The rate and quadrature-stiffness directions taken from the resonator alone are exactly the
    change between two interconnected cores (the plan builds two cores fewer)."""
    dev = load_device(device)
    dev.values["mechanics"]["duffing_k3_drive_N_per_m3"] = 1e9  # a describing-function stiffness too
    dg = build_diagram(dev, T)
    ss = steady_state(dg)
    kx = dg.resonator.duffing_stiffness(ss.amplitude_m)
    core0 = dg.core_system(ss.modulator_gain, 0.0, kx)
    A0 = np.asarray(core0.A)
    Aw = np.asarray(dg.core_system(ss.modulator_gain, 1.0, kx).A) - A0
    Aq = np.asarray(dg.core_system(ss.modulator_gain, 0.0, kx, 1.0).A) - A0
    assert np.array_equal(_resonator_direction(dg, core0, kx, 1.0, 0.0), Aw)
    assert np.array_equal(_resonator_direction(dg, core0, kx, 0.0, 1.0), Aq)
    assert np.count_nonzero(Aw) == 2 and np.count_nonzero(Aq) == 2
