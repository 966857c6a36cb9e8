"""Effect fitting (fmvmg_sim.diagnosis.model): a path effect's nonlinear parameter from a noise-free record."""

import numpy as np

from fmvmg_sim.diagnosis.calibrate import calibrate
from fmvmg_sim.diagnosis.data import prepare
from fmvmg_sim.diagnosis.fitting import Fitter
from fmvmg_sim.diagnosis.forward import CHANNELS
from fmvmg_sim.diagnosis.model import EffectModel
from fmvmg_sim.record import read_record
from fmvmg_sim.scenario import load_scenario
from tests.test_diagnosis_helpers import NOMINAL, oven_record


def test_thermal_lag_time_constant_recovered_to_1e4(tmp_path):
    """A strong lag (the die 10 K behind the case on 1 K/min ramps) is in the model family: the fit must
    find its time constant to a few 1e-4 (the quasi-static model's accuracy on the ramps' corners) and leave the most
    temperature-sensitive channel (the drive frequency) at the model's accuracy. A time constant 0.2 % off leaves a
    misfit of many block sigmas there, which a spurious second effect then buys."""
    tau = 700.0
    rec, _ = oven_record(tmp_path, "lag", {"thermal_lag": {"tau_s": tau, "offset_K": 0.0}}, noise=False)
    dev = load_scenario(NOMINAL).device_nominal
    f = Fitter(prepare(read_record(rec), dev.nominal_scale_factor_V_per_dps), dev)
    rows = np.ones(f.prep.n_blocks, bool)
    cal = calibrate(f, rows)
    ifr = CHANNELS.index("drive_frequency_Hz")
    z_nominal = f.residual(cal.lin.predict(cal.solution.x))[:, ifr]
    assert np.sqrt(np.nanmean(z_nominal ** 2)) > 100.0      # the lag's signature: the check is not vacuous
    mf = EffectModel(f, cal, ["thermal_lag"]).fit(rows)
    assert abs(mf.effects["thermal_lag"]["tau_s"] / tau - 1.0) < 5e-4
    z = f.residual(mf._ctx["pred"])[:, ifr]
    assert np.sqrt(np.nanmean(z ** 2)) < 1.0


def test_noise_covariance_holds_parameters_at_an_active_bound():
    """Bounded least squares: a knob the data push past its bound is held there, and an effect column nearly
    collinear with it then carries the misfit. Its standard error is that of the fit with the knob fixed (the
    bound removed the collinearity); with every parameter free it would be 20x larger, and a significance test
    reading it would reject a well-determined effect. Away from the bounds the covariance is the usual one."""
    from types import SimpleNamespace

    from fmvmg_sim.diagnosis.fitting import Lin
    n, sigma = 400, 0.01
    t = np.linspace(0.0, 1.0, n)
    cols = np.stack([np.ones(n), 1.0 + 0.05 * t], axis=-1)[:, None, :]           # (n, C=1, K=2)
    rng = np.random.default_rng(3)

    def fit(a_true, b_true):
        y = (a_true * cols[:, 0, 0] + b_true * cols[:, 0, 1] + sigma * rng.standard_normal(n))[:, None]
        f = SimpleNamespace(S=np.full((n, 1), sigma), Y=y, present=np.array([True]))
        lin = Lin(np.zeros((n, 1)), cols, ["knob", "effect.amp"], np.zeros(2), np.array([np.nan, np.nan]),
                  np.array([-1.0, -10.0]), np.array([1.0, 10.0]))
        return Fitter.solve(f, lin, np.ones(n, bool))

    sol = fit(1.5, 0.0)                               # the knob wants 1.5: held at its bound 1
    assert sol.x[0] == 1.0 and 0.3 < sol.x[1] < 0.6
    c = cols[:, 0, 1]
    assert sol.cov_noise[0, 0] == 0.0 and sol.cov_noise[0, 1] == 0.0
    assert np.isclose(np.sqrt(sol.cov_noise[1, 1]), sigma / np.sqrt(np.sum(c ** 2)), rtol=1e-9)
    H = np.einsum("nk,nl->kl", cols[:, 0, :], cols[:, 0, :]) / sigma ** 2
    assert np.sqrt(np.linalg.inv(H)[1, 1]) > 20 * np.sqrt(sol.cov_noise[1, 1])
    free = fit(0.5, 0.2)                              # inside the bounds: the ordinary inverse
    assert np.allclose(free.cov_noise, np.linalg.inv(H), rtol=1e-6)


def test_covariance_scales_each_channel_by_its_own_misfit():
    """A knob read from a well-fitted channel keeps its white-noise error when another channel carries a
    large unmodelled wander; the knob that channel determines is widened by that channel's own reduced
    chi-square. (A global reduced chi-square would widen both by about 7x here.)"""
    from types import SimpleNamespace

    from fmvmg_sim.diagnosis.fitting import Lin
    n, sigma = 500, 0.01
    t = np.linspace(0.0, 1.0, n)
    cols = np.zeros((n, 2, 2))
    cols[:, 0, 0] = 1.0                               # knob 0: an offset in channel 0 only
    cols[:, 1, 1] = 1.0                               # knob 1: an offset in channel 1 only
    rng = np.random.default_rng(5)
    y = np.column_stack([0.3 + 10 * sigma * np.sin(2 * np.pi * 3 * t) + sigma * rng.standard_normal(n),
                         -0.2 + sigma * rng.standard_normal(n)])
    f = SimpleNamespace(S=np.full((n, 2), sigma), Y=y, present=np.array([True, True]))
    lin = Lin(np.zeros((n, 2)), cols, ["a", "b"], np.zeros(2), np.array([np.nan, np.nan]),
              np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    sol = Fitter.solve(f, lin, np.ones(n, bool))
    assert np.allclose(sol.x, y.mean(axis=0), atol=1e-9)
    red = [np.sum((y[:, c] - y[:, c].mean()) ** 2) / sigma ** 2 / (n - 1) for c in range(2)]
    assert red[0] > 40 and red[1] < 1.2
    sd = np.sqrt(np.diag(sol.cov))
    assert np.isclose(sd[0], np.sqrt(red[0]) * sigma / np.sqrt(n), rtol=1e-6)
    assert np.isclose(sd[1], np.sqrt(max(red[1], 1.0)) * sigma / np.sqrt(n), rtol=1e-6)
    assert np.allclose(np.sqrt(np.diag(sol.cov_noise)), sigma / np.sqrt(n), rtol=1e-6)  # the noise model alone


def test_prediction_sd_is_the_regression_band():
    """``Lin.predict_sd`` of a straight line fitted on t in [0, 1] is the textbook sd of the fitted mean,
    sigma sqrt(1/n + (t - mean t)^2 / Sxx): small inside the data, growing where the fit extrapolates (t = 3)."""
    from types import SimpleNamespace

    from fmvmg_sim.diagnosis.fitting import Lin
    n, sigma = 200, 0.05
    t = np.concatenate([np.linspace(0.0, 1.0, n), [3.0]])
    cols = np.zeros((n + 1, 1, 2))
    cols[:, 0, 0] = 1.0
    cols[:, 0, 1] = t
    rng = np.random.default_rng(11)
    y = (0.4 - 0.7 * t + sigma * rng.standard_normal(n + 1))[:, None]
    f = SimpleNamespace(S=np.full((n + 1, 1), sigma), Y=y, present=np.array([True]))
    lin = Lin(np.zeros((n + 1, 1)), cols, ["a", "b"], np.zeros(2), np.array([np.nan, np.nan]),
              np.array([-10.0, -10.0]), np.array([10.0, 10.0]))
    train = np.arange(n + 1) < n                       # the point at t = 3 is held out
    sol = Fitter.solve(f, lin, train)
    sd = lin.predict_sd(sol.param_cov(), np.ones(n + 1, bool))[:, 0]
    tt = t[:n]
    band = sigma * np.sqrt(1.0 / n + (t - tt.mean()) ** 2 / np.sum((tt - tt.mean()) ** 2))
    assert np.allclose(sd, band, rtol=1e-6)
    assert sd[-1] > 5 * sd[n // 2]                     # extrapolating to t = 3 is far less certain
