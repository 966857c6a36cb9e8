"""The averaged (envelope) model against the carrier model at -40, 25 and 85 C."""

import numpy as np
import pytest

from fmvmg_sim.analysis import allan_deviation
from fmvmg_sim.averaged import steady_state
from fmvmg_sim.numerics.discretize import foh, noise_covariance
from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.diagram import build_diagram
from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.scenario import load_scenario

RATE_STEPS = """
[rate]
start_dps = 0.0
segments = [ { hold_s = 0.4 }, { step_to_dps = 20.0 }, { hold_s = 0.4 }, { step_to_dps = -20.0 } ]
"""


def _both(path, **kw):
    out = {}
    for fid in ("carrier", "envelope"):
        scn = load_scenario(path, fidelity=fid, **kw)
        out[fid] = run_carrier(scn, progress=False) if fid == "carrier" else run_envelope(scn, progress=False)
    return out


def _mean(res, name, a, b):
    t = res.time_s
    return float(np.mean(res[name][(t > a) & (t < b)]))


@pytest.mark.parametrize("T", [-40.0, 25.0, 85.0])
def test_envelope_agrees_with_carrier(make_scenario, T):
    runs = _both(make_scenario(RATE_STEPS, duration_s=1.2, temperature_C=T))
    c, e = runs["carrier"], runs["envelope"]
    amp = [_mean(r, "drive_displacement_amplitude_m", 0.1, 0.4) for r in (c, e)]
    eff = [_mean(r, "agc_effort_V", 0.1, 0.4) for r in (c, e)]
    bias = [_mean(r, "rate_dps", 0.2, 0.4) for r in (c, e)]
    sf = [(_mean(r, "rate_V", 0.6, 0.8) - _mean(r, "rate_V", 1.0, 1.2)) / 40.0 for r in (c, e)]
    freq = [_mean(r, "drive_frequency_Hz", 0.1, 0.4) for r in (c, e)]
    assert amp[1] == pytest.approx(amp[0], rel=1e-3)
    assert eff[1] == pytest.approx(eff[0], rel=5e-3)
    assert sf[1] == pytest.approx(sf[0], rel=5e-3)
    assert abs(bias[1] - bias[0]) <= max(0.01 * abs(bias[0]), 0.01)
    assert freq[1] == pytest.approx(freq[0], abs=0.01)


@pytest.mark.parametrize("T", [-40.0, 25.0, 85.0])
def test_vref_step_response_agrees(make_scenario, T):
    body = "[vref]\nsegments = [ { hold_s = 0.1 }, { step_to_factor = 1.1 } ]\n"
    path = make_scenario(body, duration_s=0.4, temperature_C=T, output_rate_Hz=2000.0)
    runs = _both(path, overrides=["scenario.envelope_step_s=0.0005"])
    c, e = runs["carrier"], runs["envelope"]
    t = e.time_s
    rc = np.interp(t, c.time_s, c["drive_amplitude_V"])
    step = 0.1 * build_diagram(load_scenario(path).device, T).vref_V
    win = t > 0.1
    rms = np.sqrt(np.mean((e["drive_amplitude_V"][win] - rc[win]) ** 2))
    assert rms <= 0.02 * step
    assert e["drive_amplitude_V"][-1] == pytest.approx(1.1 * step * 10, rel=1e-3)


def test_white_noise_level_matches_the_analytic_arw(make_scenario):
    """Electronic white noise only: the ARW of the rate output equals the front-end density through the chain."""
    path = make_scenario(duration_s=400.0, output_rate_Hz=100.0)
    scn = load_scenario(path, fidelity="envelope", overrides=["noise.electronic=true"])
    res = run_envelope(scn, progress=False)
    dg = build_diagram(scn.device, 25.0)
    ss = steady_state(dg)
    e_n = scn.device.values["noise"]["sense_input_V_per_sqrtHz"]
    # demodulated one-sided PSD at baseband: (G_out K_m |R| / 2)^2 * 2 e_n^2 |H_se|^2
    s_V = (dg.output_lpf.gain * dg.demodulator.k_per_V * abs(ss.R_I) / 2) ** 2 * 2 * e_n ** 2 \
        * abs(dg.sense_amps_response(ss.omega_rad_s)) ** 2
    sf = res.info["nominal_scale_factor_V_per_dps"]
    n_expected = np.sqrt(s_V / 2) / sf  # deg/s/sqrt(Hz) -> Allan N in deg/sqrt(s)
    x = res["rate_dps"][1000:]
    m = 100  # 1 s clusters
    y = x[: len(x) // m * m].reshape(-1, m).mean(axis=1)
    adev_1s = np.sqrt(0.5 * np.mean(np.diff(y) ** 2))
    assert adev_1s == pytest.approx(n_expected, rel=0.06)
    assert allan_deviation(x, 100.0).N == pytest.approx(n_expected, rel=0.02)  # the fitted white term


def test_foh_is_exact_for_ramps():
    A = np.array([[-3.0, 10.0], [-10.0, -1.0]])
    B = np.array([[0.0], [2.0]])
    h = 0.3
    Phi, G0, G1 = foh(A, B, h)
    from scipy.integrate import solve_ivp
    sol = solve_ivp(lambda t, x: A @ x + B[:, 0] * (1.5 - 2.2 * t / h), (0, h), [0.2, 0.1], rtol=1e-12, atol=1e-14)
    assert np.allclose(sol.y[:, -1], Phi @ [0.2, 0.1] + G0[:, 0] * 1.5 + G1[:, 0] * (-0.7), atol=1e-10)


def test_noise_covariance_matches_lyapunov():
    from scipy.linalg import solve_continuous_lyapunov, solve_discrete_lyapunov
    A = np.array([[-3.0, 10.0], [-10.0, -1.0]])
    Qc = np.diag([1.0, 2.0])
    Qd = noise_covariance(A, np.eye(2), Qc, 0.3)
    Phi, _, _ = foh(A, np.zeros((2, 1)), 0.3)
    assert np.allclose(solve_discrete_lyapunov(Phi, Qd), solve_continuous_lyapunov(A, -Qc), atol=1e-12)


def test_noise_covariance_of_a_long_step_on_a_stiff_system():
    """A step a thousand times the fastest time constant (where one Van Loan exponential overflows): the
    covariance is still the stationary one minus what the step's transition carries over, to 1e-10."""
    from scipy.linalg import expm, solve_continuous_lyapunov
    A = np.array([[-1.0, 3.0, 0.0], [0.0, -50.0, 100.0], [0.0, 0.0, -5000.0]])
    G = np.array([[0.3, 0.0], [1.0, -0.5], [0.2, 2.0]])
    Qc = np.diag([1.0, 2.0])
    P = solve_continuous_lyapunov(A, -G @ Qc @ G.T)
    for h in (1e-4, 0.01, 0.2):
        Phi = expm(A * h)
        ref = P - Phi @ P @ Phi.T
        assert np.max(np.abs(noise_covariance(A, G, Qc, h) - ref)) < 1e-10 * np.max(np.abs(ref))


def test_envelope_steps_up_to_the_longest_allowed_give_the_same_noise():
    """The population study's long steps: 0.1 s steps run (the step's noise covariance stays positive
    definite) and give the rate output's short-term noise of 0.01 s steps, flicker included."""
    from fmvmg_sim.api import simulate
    sigma = []
    for h in (0.01, 0.1):
        res = simulate("static_25C", ["scenario.output_rate_Hz=1", "scenario.duration_s=4000",
                                      f"scenario.envelope_step_s={h}"], fidelity="envelope")
        x = np.asarray(res["rate_dps"])[100:]
        sigma.append(np.std(np.diff(x)) / np.sqrt(2))
    assert sigma[1] == pytest.approx(sigma[0], rel=0.05)


def test_noise_factor_reproduces_badly_scaled_covariances():
    """States in metres and volts side by side; a state the noise cannot reach gets no noise."""
    from fmvmg_sim.numerics.discretize import noise_factor
    A = np.array([[-5.0, 0.0, 0.0], [2e8, -300.0, 0.0], [0.0, 1.0, -1.0]])  # x0 in m drives x1 in V
    G = np.array([[1e-9, 0.0], [0.0, 1.0], [0.0, 0.0]])
    Qc = np.diag([1.0, 1e-8])
    L = noise_factor(A, G, Qc, 0.01)
    Q = noise_covariance(A, G, Qc, 0.01)
    d = np.sqrt(np.diag(Q))
    assert np.allclose((L @ L.T) / np.outer(d, d), Q / np.outer(d, d), atol=1e-9)
    L2 = noise_factor(A, G, np.diag([0.0, 1e-8]), 0.01)
    assert np.all(L2[0] == 0)  # the first state is not reachable from the remaining noise


@pytest.mark.parametrize("offsets", [(0.0, 0.0), (-22.0, 8.0)], ids=["board-on-die", "board-off-die"])
def test_temperature_interpolation_of_the_discretised_model_is_accurate(offsets):
    """The parameter table against the model discretised directly, at die temperatures and board-minus-die
    offsets between the nodes (a 1-D spline when the board follows the die, a tensor spline when not)."""
    from fmvmg_sim.device import load_device
    from fmvmg_sim.envelope.engine import _ParamTable
    from fmvmg_sim.envelope.model import PARAMS, operating_params
    dev = load_device("fmvmg_a")
    on = {"brownian": True, "electronic": True}
    lo, hi = offsets
    tab = _ParamTable(dev, 0.01, on, -40.0, 85.0, lo, hi)
    assert len(tab.offsets) == (1 if lo == hi else 4)
    for T, w in ((12.34, 0.13), (-33.3, 0.58), (71.7, 0.91)):
        off = lo + w * (hi - lo)
        Pi = tab(np.array([T]), np.array([off]))[0]
        Pd = PARAMS.pack(operating_params(build_diagram(dev, T, board_C=T + off), 0.01, on))
        for name, sl in PARAMS.slices.items():
            if name == "L":  # compare the covariances the factors stand for
                shape = PARAMS.shapes["L"]
                Li, Ld = Pi[sl].reshape(shape), Pd[sl].reshape(shape)
                Qi, Qd = Li @ Li.T, Ld @ Ld.T
                d = np.sqrt(np.clip(np.diag(Qd), 1e-300, None))
                assert np.max(np.abs(Qi - Qd) / np.outer(d, d)) <= 1e-4, (T, name)  # in correlation units
                continue
            scale = max(np.max(np.abs(Pd[sl])), 1e-300)
            assert np.max(np.abs(Pi[sl] - Pd[sl])) <= 1e-6 * scale, (T, name)
