"""The PLL drive's blocks: the controlled oscillator and the quadrature detector, each face against the others."""

import casadi as ca
import numpy as np
import pytest

from blocks.nco import ControlledOscillator
from blocks.phase_detector import QuadratureDetector
from fmvmg_sim.compiled import CasadiOps


def test_oscillator_phase_advances_at_its_tuned_frequency():
    nco = ControlledOscillator(f_free_Hz=1000.0, k_vco_Hz_per_V=50.0)
    h, n, v = 1e-5, 12345, 0.4
    th = 0.3
    for _ in range(n):
        th, c, s = nco.carrier_step(th, v, h)
    expected = 0.3 + 2 * np.pi * (1000.0 + 50.0 * v) * n * h
    assert -np.pi <= th < np.pi
    assert np.angle(np.exp(1j * (th - expected))) == pytest.approx(0.0, abs=1e-9)
    assert (c, s) == (pytest.approx(np.cos(th)), pytest.approx(np.sin(th)))
    assert nco.omega_rad_s(v) == pytest.approx(2 * np.pi * 1020.0)


def test_oscillator_linear_face_is_the_phase_integrator():
    nco = ControlledOscillator(k_vco_Hz_per_V=80.0)
    w = 2 * np.pi * 7.0
    assert nco.frequency_response(w)[0, 0] == pytest.approx(2 * np.pi * 80.0 / (1j * w))


def test_oscillator_carrier_face_builds_symbolically():
    nco = ControlledOscillator(f_free_Hz=1000.0)
    th, v = ca.SX.sym("th"), ca.SX.sym("v")
    out = ca.Function("f", [th, v], list(nco.carrier_step(th, v, 1e-4, CasadiOps())))
    assert [float(x) for x in out(3.1, 0.0)] == pytest.approx(list(nco.carrier_step(3.1, 0.0, 1e-4)))


@pytest.mark.parametrize("k", [0.0, -50.0])
def test_oscillator_refuses_a_non_positive_gain(k):
    with pytest.raises(ValueError, match="k_vco_Hz_per_V"):
        ControlledOscillator(k_vco_Hz_per_V=k)


@pytest.mark.parametrize("V", [0.7 * np.exp(-1j * 1.2), 0.3 + 0.05j, -0.2j])
def test_detector_carrier_mean_over_a_period_is_its_envelope_face(V):
    """32 trapezoid steps over one period give the envelope face's DC outputs exactly (the 2-omega parts cancel)."""
    det = QuadratureDetector(trim_rad=-0.4, k_pd=1.3, k_amp=0.6)
    th = 2 * np.pi * np.arange(33) / 32 + 0.25
    v = np.real(V * np.exp(1j * th))
    pd, amp = det.carrier_mean(v[:-1], v[1:], np.cos(th[:-1]), np.sin(th[:-1]), np.cos(th[1:]), np.sin(th[1:]))
    assert (np.mean(pd) / 2, np.mean(amp) / 2) == (pytest.approx(det.baseband(V)[0] / 2, abs=1e-12),
                                                  pytest.approx(det.baseband(V)[1] / 2, abs=1e-12))


def test_detector_reads_phase_error_and_amplitude():
    """A pickoff V sin(theta + trim + eps): the detector reads K_pd V sin(eps), the amplitude channel K_amp V cos(eps)."""
    det = QuadratureDetector(trim_rad=0.3, k_pd=1.0, k_amp=2 / np.pi)
    V, eps = 0.7, 0.05
    phasor = V * np.exp(1j * (0.3 + eps - np.pi / 2))  # sin(x) = Re(e^{j(x - pi/2)})
    pd, amp = det.baseband(phasor)
    assert pd == pytest.approx(V * np.sin(eps), rel=1e-12)
    assert amp == pytest.approx(2 / np.pi * V * np.cos(eps), rel=1e-12)
