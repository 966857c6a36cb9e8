"""Each block on its own: linear faces against python-control, carrier faces against brute force."""

import copy
import dataclasses

import control
import numpy as np
import pytest

from blocks import (AllPassPhaseShifter, CapacitivePickoff, DifferentialAmplifier, ElectrostaticDrive,
                    FullWaveRectifier, LowPass1, LowPass2, Multiplier, PIController, QuadratureTuningElectrodes,
                    RebalanceController, SummingJunction, TwoModeResonator)
from blocks.base import LinearBlock
from fmvmg_sim.numerics.discretize import expm_derivative, zoh

LINEAR_BLOCKS = [
    TwoModeResonator(q_drive=50.0, q_sense=40.0, k_quad_N_per_m=300.0, rate_rad_s=100.0),
    CapacitivePickoff(c_feedthrough_F=1e-15),
    SummingJunction(signs=(1.0, -1.0)),
    ElectrostaticDrive(),
    DifferentialAmplifier(gain=20.0, gbw_Hz=20e6),
    AllPassPhaseShifter.designed_for(30740.0),
    LowPass1(f_c_Hz=100.0, gain=2.0),
    LowPass2(f_c_Hz=200.0, gain=5.0),
    PIController(kp=68.0, ki_per_s=330.0),
    RebalanceController(f_c_Hz=2000.0, kp=4.0, ki_per_s=2500.0, kd_s=0.0156),
    QuadratureTuningElectrodes(dk_dV_N_per_m_per_V=0.1),
]


@pytest.mark.parametrize("blk", LINEAR_BLOCKS, ids=lambda b: type(b).__name__)
def test_discrete_step_matches_python_control(blk):
    """The engines' exact discretisation reproduces python-control's continuous step response."""
    sys = blk.linear_model()
    A, B, C, D = (np.asarray(m, float) for m in (sys.A, sys.B, sys.C, sys.D))
    pole = np.max(np.abs(np.linalg.eigvals(A))) if A.size and np.any(A) else 1.0
    h = 0.05 / pole
    n = 400
    Phi, Gam = zoh(A, B, h)
    t = np.arange(n) * h
    ref = control.step_response(sys, T=t, input=0).outputs  # (outputs, time) for the first input
    ref = np.atleast_2d(ref).reshape(C.shape[0], -1)
    x = np.zeros(A.shape[0])
    y = []
    for _ in range(n):
        y.append(C @ x + D[:, 0])
        x = Phi @ x + Gam[:, 0]
    y = np.array(y).T
    for k in range(C.shape[0]):
        scale = max(1e-300, np.max(np.abs(ref[k])))
        assert np.allclose(y[k], ref[k], rtol=1e-6, atol=1e-9 * scale), k


@pytest.mark.parametrize("blk", LINEAR_BLOCKS, ids=lambda b: type(b).__name__)
def test_frequency_response_matches_python_control(blk):
    """The envelope face (cached matrices) equals python-control's evaluation of the named model."""
    for w in (2 * np.pi * 200.0, 2 * np.pi * 30740.0, 2 * np.pi * 61480.0):
        ref = np.asarray(control.frequency_response(blk.linear_model(), [w]).complex)
        ref = ref.reshape(len(blk.outputs), len(blk.inputs))
        assert np.allclose(blk.frequency_response(w), ref, rtol=1e-12, atol=0.0)


def test_frequency_response_follows_a_parameter_change():
    """A block's cached matrices are rebuilt when one of its parameters is changed in place."""
    amp = DifferentialAmplifier(gain=20.0, gbw_Hz=20e6)
    w = 2 * np.pi * 30740.0
    before = amp.frequency_response(w)[0, 0]
    amp.gbw_Hz = 2e6  # ten times the lag
    after = amp.frequency_response(w)[0, 0]
    assert -np.angle(after) == pytest.approx(np.arctan(w / (2 * np.pi * 2e6 / 20.0)), rel=1e-12)
    assert np.tan(-np.angle(after)) == pytest.approx(10 * np.tan(-np.angle(before)), rel=1e-12)
    amp.gbw_Hz = 20e6
    assert amp.frequency_response(w)[0, 0] == before


@pytest.mark.parametrize("blk", LINEAR_BLOCKS, ids=lambda b: type(b).__name__)
def test_cached_matrices_are_the_named_models(blk):
    """The envelope face's matrices (built from ``abcd`` where a block has it) equal the named model's, bit for bit,
    before and after a parameter changes, and the named model carries the block's state names."""
    sys = blk.linear_model()
    for got, ref in zip(blk.state_space_matrices(), (sys.A, sys.B, sys.C, sys.D)):
        assert got.dtype == float and np.array_equal(got, np.asarray(ref, float))
    if type(blk).abcd is not LinearBlock.abcd:
        assert sys.state_labels == list(blk.states)
        changed = copy.deepcopy(blk)
        name = next(f.name for f in dataclasses.fields(changed) if isinstance(getattr(changed, f.name), float))
        setattr(changed, name, 1.37 * getattr(changed, name))
        sys2 = changed.linear_model()
        for got, ref in zip(changed.state_space_matrices(), (sys2.A, sys2.B, sys2.C, sys2.D)):
            assert np.array_equal(got, np.asarray(ref, float))


def test_amplifier_gain_and_lag():
    amp = DifferentialAmplifier(gain=20.0, gbw_Hz=20e6)
    H = amp.frequency_response(2 * np.pi * 30740.0)[0, 0]
    assert abs(H) == pytest.approx(20.0 / np.hypot(1, 30740 * 20 / 20e6), rel=1e-12)
    # physics brief: lag ~ G f / GBW
    assert -np.angle(H) == pytest.approx(20 * 30740 / 20e6, rel=1e-3)
    assert amp.phase_lag_rad(30740.0) == pytest.approx(-np.angle(H), rel=1e-12)


def test_phase_shifter_90_degrees_and_frequency_slope():
    ps = AllPassPhaseShifter.designed_for(30740.0)
    w = 2 * np.pi * 30740.0
    H = ps.frequency_response(w)[0, 0]
    assert abs(H) == pytest.approx(1.0, abs=1e-12)
    assert np.angle(H) == pytest.approx(np.pi / 2, abs=1e-12)
    # d phase / d ln f = -1 rad at the design point (physics brief section 2)
    d = 1e-4
    slope = (ps.phase_lead_rad(30740.0 * (1 + d)) - ps.phase_lead_rad(30740.0 * (1 - d))) / (2 * d)
    assert slope == pytest.approx(-1.0, rel=1e-6)
    # temperature moves the phase through RC: -(TCR+TCC) dT rad
    hot = AllPassPhaseShifter.designed_for(30740.0, tc_rc_per_K=50e-6, delta_T_K=60.0)
    assert hot.phase_lead_rad(30740.0) - np.pi / 2 == pytest.approx(-50e-6 * 60, rel=3e-3)  # first order in dT
    trimmed = AllPassPhaseShifter.designed_for(30740.0, trim_rad=0.1)
    assert trimmed.phase_lead_rad(30740.0) == pytest.approx(np.pi / 2 + 0.1, abs=1e-12)


def test_lowpass2_corner_and_ripple():
    lp = LowPass2(f_c_Hz=200.0, gain=1.0)
    assert abs(lp.frequency_response(0.0)[0, 0]) == pytest.approx(1.0)
    assert abs(lp.frequency_response(2 * np.pi * 200.0)[0, 0]) == pytest.approx(1 / np.sqrt(2), rel=1e-9)
    # 2f ripple of the rectified 30.74 kHz drive: (4/(3 pi)) (200/61480)^2 ~ 4.5e-6 (brief: 4e-6)
    ripple = 4 / (3 * np.pi) * abs(lp.frequency_response(2 * np.pi * 61480.0)[0, 0])
    assert 3e-6 < ripple < 6e-6


@pytest.mark.parametrize("phase", [0.0, 0.3, -0.0982, -0.02, 1.7, np.pi - 0.05])
def test_rectifier_exact_mean_over_a_step(phase):
    r = FullWaveRectifier(gain=1.3, offset_V=0.01)
    w, h = 2 * np.pi * 30740.0, 1 / (32 * 30740.0)
    t = np.linspace(0, h, 400001)
    v = 0.7 * np.sin(w * t + phase)
    exact = 1.3 * np.trapezoid(np.abs(v), t) / h + 0.01
    assert r.carrier_mean(v[0], v[-1], r.carrier_constants(w, h)) == pytest.approx(exact, rel=1e-8)


def test_rectifier_second_harmonic_is_the_fourier_coefficient_of_abs_cos():
    r = FullWaveRectifier(gain=2.5)
    th = np.linspace(0, 2 * np.pi, 100001)
    a2 = np.trapezoid(2.5 * np.abs(np.cos(th)) * np.cos(2 * th), th) / np.pi
    assert r.second_harmonic_gain() == pytest.approx(a2, rel=1e-8)


def test_rectifier_describing_gain_is_mean_of_abs_sine():
    r = FullWaveRectifier(gain=1.0)
    th = np.linspace(0, 2 * np.pi, 100001)
    assert r.describing_gain() == pytest.approx(np.trapezoid(np.abs(np.sin(th)), th) / (2 * np.pi), rel=1e-8)
    with pytest.raises(ValueError):
        r.carrier_constants(2 * np.pi * 1000, 1e-3)  # fewer than 2 steps per cycle


def test_pi_anti_windup_holds_integrator_in_saturation():
    pi = PIController(kp=1.0, ki_per_s=100.0, u_min_V=0.0, u_max_V=1.0)
    integ, u = 0.0, 0.0
    for _ in range(1000):
        integ, u = pi.carrier_step(integ, 5.0, 1e-3)
    assert u == 1.0
    # the integrator stopped once the output saturated: it is not 5 V s deep
    assert integ < 0.02
    # unsaturated it integrates exactly
    integ2, u2 = pi.carrier_step(0.0, 0.001, 1e-3)
    assert integ2 == pytest.approx(1e-6) and u2 == pytest.approx(0.001 + 100 * 1e-6)


def test_multiplier_baseband_matches_time_average():
    m = Multiplier(k_per_V=2.0)
    A, B = 0.7 * np.exp(0.3j), 1.1 * np.exp(-0.5j)
    th = np.linspace(0, 2 * np.pi, 200001)[:-1]
    prod = 2.0 * np.real(A * np.exp(1j * th)) * np.real(B * np.exp(1j * th))
    assert m.baseband(A, B) == pytest.approx(prod.mean(), rel=1e-9)


def test_comb_drive_forces():
    pp = ElectrostaticDrive(dC_dx_F_per_m=7.1e-8, vdc_V=10.0, topology="push-pull", asymmetry=0.01)
    v = 0.8
    c = 7.1e-8
    full = 0.5 * c * 1.01 * (10 + v) ** 2 - 0.5 * c * 0.99 * (10 - v) ** 2
    assert pp.linear_coef_N_per_V * v + pp.quadratic_force(v) == pytest.approx(full, rel=1e-12)
    ss = ElectrostaticDrive(dC_dx_F_per_m=c, vdc_V=10.0, topology="single-sided")
    assert ss.linear_coef_N_per_V * v + ss.quadratic_force(v) == pytest.approx(0.5 * c * (10 + v) ** 2, rel=1e-12)


def test_pickoff_and_junction_gains():
    p = CapacitivePickoff(bias_V=5.0, dC_dx_F_per_m=7e-8, c_feedback_F=2e-12, c_feedthrough_F=2e-15, sign=-1.0)
    D = np.asarray(p.linear_model().D)
    assert D[0, 0] == pytest.approx(-1.75e5) and D[0, 1] == pytest.approx(1e-3)
    assert np.asarray(SummingJunction(signs=(1.0, -1.0)).linear_model().D).tolist() == [[1.0, -1.0]]


def test_resonator_eigenvalues_are_the_modes():
    r = TwoModeResonator(q_drive=2e4, q_sense=1e4)
    lam = np.linalg.eigvals(r.state_matrix())
    wd, ws = 2 * np.pi * 30740.0, 2 * np.pi * 30886.0
    top = sorted(lam[lam.imag > 0], key=lambda z: z.imag)
    assert top[0].imag == pytest.approx(wd * np.sqrt(1 - 1 / (4 * 2e4 ** 2)), rel=1e-12)
    assert -top[0].real == pytest.approx(wd / (2 * 2e4), rel=1e-9)
    assert -top[1].real == pytest.approx(ws / (2 * 1e4), rel=1e-9)


def test_expm_derivative_matches_finite_difference():
    rng = np.random.default_rng(0)
    A, dA = rng.standard_normal((5, 5)), rng.standard_normal((5, 5))
    from scipy.linalg import expm
    d = 1e-6
    fd = (expm((A + d * dA) * 0.1) - expm((A - d * dA) * 0.1)) / (2 * d)
    assert np.allclose(expm_derivative(A, dA, 0.1), fd, atol=1e-8)
