"""Effect fitting (fmvmg_sim.diagnosis.model): a path effect's nonlinear parameter from a noise-free record."""

import numpy as np

from fmvmg_sim.averaged import scale_factor_V_per_dps
from fmvmg_sim.diagnosis.calibrate import calibrate
from fmvmg_sim.diagnosis.data import prepare
from fmvmg_sim.diagnosis.fitting import Fitter
from fmvmg_sim.diagnosis.forward import CHANNELS
from fmvmg_sim.diagnosis.model import EffectModel
from fmvmg_sim.diagram import build_diagram
from fmvmg_sim.record import read_record
from fmvmg_sim.scenario import load_scenario
from tests.test_diagnosis_helpers import NOMINAL, oven_record


def test_thermal_lag_time_constant_recovered_to_1e4(tmp_path):
    """A strong lag (the die 10 K behind the case on 1 K/min ramps) is in the model family: the fit must
    find its time constant to ~1e-4 and leave the most temperature-sensitive channel (the drive frequency)
    at the model's accuracy. A time constant 0.2 % off (the former search tolerance) leaves a misfit of many
    block sigmas there, which a spurious second effect then buys."""
    tau = 700.0
    rec, _ = oven_record(tmp_path, "lag", {"thermal_lag": {"tau_s": tau, "offset_K": 0.0}}, noise=False)
    dev = load_scenario(NOMINAL).device_nominal
    sf = scale_factor_V_per_dps(build_diagram(dev, dev.reference_temperature_C))
    f = Fitter(prepare(read_record(rec), sf), dev)
    rows = np.ones(f.prep.n_blocks, bool)
    cal = calibrate(f, rows)
    ifr = CHANNELS.index("drive_frequency_Hz")
    z_nominal = f.residual(cal.lin.predict(cal.solution.x))[:, ifr]
    assert np.sqrt(np.nanmean(z_nominal ** 2)) > 100.0      # the lag's signature: the check is not vacuous
    mf = EffectModel(f, cal, ["thermal_lag"]).fit(rows)
    assert abs(mf.effects["thermal_lag"]["tau_s"] / tau - 1.0) < 2e-4
    z = f.residual(mf._ctx["pred"])[:, ifr]
    assert np.sqrt(np.nanmean(z ** 2)) < 1.0
