"""Record fitting (fmvmg_sim.diagnosis.fitting): response tables kept by their exact inputs."""

import numpy as np

from fmvmg_sim.diagnosis.data import prepare
from fmvmg_sim.diagnosis.fitting import Fitter
from fmvmg_sim.diagnosis.forward import response_table
from fmvmg_sim.diagnosis.parameters import apply_nominal
from fmvmg_sim.record import read_record
from fmvmg_sim.scenario import load_scenario
from tests.test_diagnosis_helpers import NOMINAL, oven_record


def test_a_table_asked_for_again_is_the_same_table_and_not_shared(tmp_path):
    """The second request for a table with the same inputs builds nothing and returns the first build's
    numbers exactly, in arrays of its own; another knob value or effect builds afresh and equals a direct
    build of that device."""
    rec, _ = oven_record(tmp_path, "plain", noise=False, duration_s=3600.0)
    dev = load_scenario(NOMINAL).device_nominal
    sf = dev.nominal_scale_factor_V_per_dps
    f = Fitter(prepare(read_record(rec), sf), dev)
    theta = {"q_drive_rel": 0.01, "split_Hz": -0.5}
    eff = {"q_factor_drift": {"q_tc_per_K": -2e-3}}
    a = f.table(theta, eff, quad=True)
    b = f.table(dict(theta), {"q_factor_drift": dict(eff["q_factor_drift"])}, quad=True)
    assert f.table_builds == 1
    for x, y in ((a.base, b.base), (a.d_rate, b.d_rate), (a.d_quad, b.d_quad)):
        assert np.array_equal(x, y) and x is not y
    b.base[:] = 0.0                                                   # a caller's change stays its own
    assert np.array_equal(f.table(theta, eff, quad=True).base, a.base)
    c = f.table(dict(theta, split_Hz=-0.4), eff, quad=True)
    d = f.table(theta, {"q_factor_drift": {"q_tc_per_K": -1e-3}}, quad=True)
    assert f.table_builds == 3
    direct = response_table(f.device(dict(theta, split_Hz=-0.4), eff), f.grid, with_rate=f.has_rate, with_quad=True)
    assert np.array_equal(c.base, direct.base)
    assert not np.array_equal(c.base, a.base) and not np.array_equal(d.base, a.base)


def test_fitters_on_one_profile_share_a_table_store(tmp_path):
    """Two records of one oven profile (another effect, another noise seed) put their Fitters on one temperature
    grid: with a shared store the second builds nothing for the first's inputs and gets its numbers bit for bit,
    equal to a Fitter of its own; a record on another profile, or another device, builds afresh."""
    dev = load_scenario(NOMINAL).device_nominal
    sf = dev.nominal_scale_factor_V_per_dps
    r1, _ = oven_record(tmp_path, "one", noise=False, duration_s=3600.0)
    r2, _ = oven_record(tmp_path, "two", {"q_factor_drift": {"q_tc_per_K": -2e-3}}, seed=2, duration_s=3600.0)
    cold = ("[temperature]\nstart_C = -20.0\n"
            "segments = [ { hold_s = 600.0 }, { ramp_to_C = -10.0, rate_C_per_min = 0.5 } ]\n")
    r3, _ = oven_record(tmp_path, "cold", noise=False, duration_s=3600.0, profile=cold)
    store = {}
    theta = {"q_drive_rel": 0.01}
    f1 = Fitter(prepare(read_record(r1), sf), dev, tables=store)
    a = f1.table(theta, quad=True)
    f2 = Fitter(prepare(read_record(r2), sf), dev, tables=store)
    b = f2.table(theta, quad=True)
    assert np.array_equal(f1.grid, f2.grid) and f2.table_builds == 0
    own = Fitter(prepare(read_record(r2), sf), dev).table(theta, quad=True)
    for x, y, z in ((a.base, b.base, own.base), (a.d_rate, b.d_rate, own.d_rate), (a.d_quad, b.d_quad, own.d_quad)):
        assert np.array_equal(x, y) and np.array_equal(y, z) and x is not y
    f3 = Fitter(prepare(read_record(r3), sf), dev, tables=store)
    f3.table(theta, quad=True)
    assert not np.array_equal(f3.grid, f1.grid) and f3.table_builds == 1
    other = apply_nominal(dev, {"q_drive_rel": 0.01})
    f4 = Fitter(prepare(read_record(r1), sf), other, tables=store)
    f4.table(theta, quad=True)
    assert f4.table_builds == 1
    assert not np.array_equal(f4.table(theta, quad=True).base, a.base)
