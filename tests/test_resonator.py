"""The resonator alone, discretised as the carrier engine does: ring-down, forced response, numerical damping."""

import numpy as np
import pytest

from blocks import TwoModeResonator
from fmvmg_sim.numerics.discretize import zoh


def _discrete(r, h):
    sys = r.linear_model()
    S = r.state_scale()
    A = (1 / S)[:, None] * np.asarray(sys.A) * S[None, :]
    B = (1 / S)[:, None] * np.asarray(sys.B)
    return zoh(A, B, h), S


@pytest.mark.parametrize("q", [2e4, 1e5])
def test_free_ringdown_time_constant(q):
    r = TwoModeResonator(q_drive=q, k_quad_N_per_m=0.0, c_quad_N_s_per_m=0.0)
    h = 1 / (32 * r.f_drive_Hz)
    (Phi, _), S = _discrete(r, h)
    z = np.array([1.0, 0, 0, 0])
    n_cyc = 2000
    P = np.linalg.matrix_power(Phi, 32 * n_cyc)
    z1 = P @ z
    w = 2 * np.pi * r.f_drive_Hz
    a1 = np.hypot(z1[0] * S[0], z1[1] * S[1] / w) / S[0]
    tau_meas = -(32 * n_cyc * h) / np.log(a1)
    assert tau_meas == pytest.approx(r.ringdown_time_constant_s(), rel=5e-3)


def test_numerical_damping_below_a_thousandth_of_the_physical_loss_at_q_1e5():
    """peers.md: RK4 at 32 steps/cycle adds h^6/144 per step; the exact discretisation adds none."""
    r = TwoModeResonator(q_drive=1e5)
    h = 1 / (32 * r.f_drive_Hz)
    (Phi, _), _ = _discrete(r, h)
    lam = np.linalg.eigvals(Phi[:2, :2])
    loss_per_step = 1 - np.abs(lam[0])
    physical = 1 - np.exp(-2 * np.pi * r.f_drive_Hz / (2 * 1e5) * h)
    assert abs(loss_per_step - physical) <= 1e-3 * physical
    # for contrast, classical RK4 on the same oscillator would add ~40 % of the loss
    A = r.state_matrix()[:2, :2]
    M = np.eye(2) + A * h + (A * h) @ (A * h) / 2 + np.linalg.matrix_power(A * h, 3) / 6 + np.linalg.matrix_power(A * h, 4) / 24
    rk4_extra = (1 - np.max(np.abs(np.linalg.eigvals(M)))) - physical
    assert rk4_extra > 0.2 * physical


def test_forced_amplitude_at_resonance_is_q_f_over_k():
    r = TwoModeResonator(q_drive=2e4, k_quad_N_per_m=0.0)
    h = 1 / (128 * r.f_drive_Hz)
    (Phi, Gam), S = _discrete(r, h)
    w = 2 * np.pi * r.f_drive_Hz
    F = 1e-9
    # steady state of the sampled-and-held forcing, by the discrete frequency response at w:
    # x_k = Re(X e^{i w k h}),  X = C (e^{iwh} I - Phi)^-1 Gam * F_hold, with the ZOH gain sinc(wh/2)
    # (a ZOH of a sine is a sine of amplitude sinc(wh/2) delayed by h/2)
    z = np.exp(1j * w * h)
    X = np.linalg.solve(z * np.eye(4) - Phi, Gam[:, 0])[0] * S[0] * F
    amp = abs(X) / np.sinc(w * h / 2 / np.pi)
    assert amp == pytest.approx(r.q_drive * F / r.k_drive_N_per_m, rel=5e-3)


def test_brownian_psd_is_4kTc():
    r = TwoModeResonator()
    kb = 1.380649e-23
    fd, fs = r.brownian_force_psd_N2_per_Hz()
    assert fd == pytest.approx(4 * kb * 298.15 * r.c_drive_N_s_per_m)
    assert fs == pytest.approx(4 * kb * 298.15 * r.c_sense_N_s_per_m)
