"""The drive amplitude loop's closure: its faces (set-point, carrier step, envelope rows, phasors) agree."""

import numpy as np
import pytest

from fmvmg_sim.amplitude_loop import CARRIER_FIELDS, AmplitudeLoopStep
from fmvmg_sim.averaged import steady_state
from fmvmg_sim.device import load_device
from fmvmg_sim.diagram import build_diagram
from fmvmg_sim.numerics.layout import Layout

STEPS_PER_CYCLE = 32
LAYOUT = Layout(CARRIER_FIELDS)


@pytest.fixture(scope="module", params=["fmvmg_a", "dualmass_004"])
def dg(request):
    """A diagram away from the reference temperature with a rectifier offset (the offset enters every face)."""
    dev = load_device(request.param)
    dev.values["circuit"]["rectifier"]["offset_tc_V_per_K"] = 0.002
    return build_diagram(dev, -20.0)


def _step_face(dg, omega):
    h = 2 * np.pi / omega / STEPS_PER_CYCLE
    p = LAYOUT.pack(dg.amplitude_loop.carrier_params(omega, h))
    return AmplitudeLoopStep(LAYOUT, p), h


def test_the_carrier_detector_averages_to_the_envelope_level(dg):
    """Over a cycle the carrier face's step means of the rectifier average to the describing function's level,
    whatever the sinusoid's phase against the steps; the envelope rows' sensor gain gives the same level."""
    loop = dg.amplitude_loop
    assert dg.rectifier.offset_V != 0.0
    ss = steady_state(dg)
    w = ss.omega_rad_s
    face, h = _step_face(dg, w)
    t = np.arange(STEPS_PER_CYCLE + 1) * h
    V = 0.731
    for phase in (0.0, 0.3, 1.9):
        v = V * np.cos(w * t + phase)
        mean = np.mean(face.detect(v[:-1], v[1:]))
        assert mean == pytest.approx(loop.detector_level_V(V), rel=1e-12)
    H = dg.drive_chain_response(w) * dg.phase_shifter_response(w)
    A = 3.2e-6
    rows = loop.envelope_rows(H)
    assert rows.sensor_gain * A + rows.offset_V == pytest.approx(loop.detector_level_V(abs(H) * A), rel=1e-14)


def test_the_set_point_relation_is_the_averaged_steady_state_and_its_own_inverse(dg):
    """The v_ps amplitude and drive amplitude the loop holds are the averaged steady state's, for the diagram's
    set-point and another; the detector level of the held amplitude is the set-point back."""
    loop = dg.amplitude_loop
    for vref in (dg.vref_V, 0.6 * dg.vref_V):
        ss = steady_state(dg, vref_V=vref)
        w = ss.omega_rad_s
        H = dg.drive_chain_response(w) * dg.phase_shifter_response(w)
        assert ss.v_ps_amplitude_V == pytest.approx(loop.held_amplitude_V(vref), rel=1e-12)
        assert ss.amplitude_m == pytest.approx(loop.held_drive_amplitude_m(H, vref), rel=1e-12)
        assert loop.detector_level_V(loop.held_amplitude_V(vref)) == pytest.approx(vref, rel=1e-14)
    # the normaliser's floor is its fraction of the held amplitude
    assert loop.floor_V == pytest.approx(loop.floor_rel * loop.held_amplitude_V(), rel=1e-14)


def test_the_carrier_normaliser_is_the_phasor_face_above_its_floor_and_capped_below(dg):
    """For v_x and v_ps in quadrature at equal amplitude the carrier face's normaliser is the phasor face's
    constant gain Vdac / V; below the floor it is Vdac / floor."""
    loop = dg.amplitude_loop
    face, _ = _step_face(dg, steady_state(dg).omega_rad_s)
    th = np.linspace(0.0, 2 * np.pi, 17)
    for V in (loop.held_amplitude_V(), 3.0 * loop.floor_V):
        vx, vps = V * np.sin(th), V * np.cos(th)
        assert np.allclose(face.normaliser(vx, vps), loop.carrier_gain(vx, vps), rtol=1e-14, atol=0)
        assert np.allclose(loop.carrier_gain(vx, vps), loop.vdac_V / V, rtol=1e-14, atol=0)
    small = 0.5 * loop.floor_V
    assert np.allclose(face.normaliser(small * np.sin(th), small * np.cos(th)), loop.vdac_V / loop.floor_V,
                       rtol=1e-14, atol=0)


def test_the_carrier_face_ripple_is_the_phasor_face_ripple(dg):
    """Driven by v_ps at the held amplitude, the carrier face's PI output holds the steady effort (from the
    integrator state the envelope face gives) and carries the 2-omega ripple of the phasor face, times the
    step mean's ``sinc^2(omega h)`` (the step-mean staircase's fundamental at 2 omega)."""
    loop = dg.amplitude_loop
    ss = steady_state(dg)
    w = ss.omega_rad_s
    face, h = _step_face(dg, w)
    n_cycles, n_fit = 600, 100
    n = n_cycles * STEPS_PER_CYCLE
    t = np.arange(n + 1) * h
    V_ps = loop.held_amplitude_V() * np.exp(0.4j)
    v = np.real(V_ps * np.exp(1j * w * t))
    detected = face.detect(v[:-1], v[1:])
    # the low-pass starts on its periodic steady state under the detector's staircase (the ripple's own state)
    f = loop.smoothing_step(h)
    Phi, Gam = f["Phi_amp"], f["Gam_amp"]
    cycle = np.zeros(2)
    for d in detected[:STEPS_PER_CYCLE]:
        cycle = Phi @ cycle + Gam * d
    s0 = np.linalg.solve(np.eye(2) - np.linalg.matrix_power(Phi, STEPS_PER_CYCLE), cycle)
    s, integ = list(s0), loop.integrator_state(ss.agc_effort_V)
    u = np.empty(n)
    for k in range(n):
        s, integ, u[k] = face.regulate(s, integ, detected[k], h)
    tail = slice(n - n_fit * STEPS_PER_CYCLE, n)
    assert np.mean(u[tail]) == pytest.approx(ss.agc_effort_V, rel=1e-5)
    U2 = 2.0 * np.mean(u[tail] * np.exp(-2j * w * t[1:][tail]))
    expected = np.sinc(w * h / np.pi) ** 2 * loop.effort_ripple(w, V_ps)
    assert abs(U2 / expected - 1.0) < 2e-3


def test_the_envelope_face_integrates_what_the_carrier_pi_outputs(dg):
    """The envelope face's exact integral of the free PI output over a step is the limit of the carrier face's
    PI stepped finely; the clamp state and the clamped output are the carrier face's."""
    face, _ = _step_face(dg, steady_state(dg).omega_rad_s)
    pi = face.controller
    vref, r, integ0, dt = dg.vref_V, dg.vref_V - 2e-3, 1e-3, 2e-4
    e = vref - r
    n = 20000
    integ, total = integ0, 0.0
    for _ in range(n):
        integ, u = pi.carrier_step(integ, e, dt / n)
        total += u * dt / n
    dK = integ0 * dt + 0.5 * e * dt ** 2  # the integral of I over the step
    exact = face.effort_integral(vref, vref, dt, r * dt, dK, 0.0, 0.0)
    assert total == pytest.approx(exact, rel=1e-4)
    for r, integ in ((vref - 0.5, 0.02), (vref + 0.5, 0.0), (vref - 1e-3, 1e-3), (vref + 0.2, 0.1)):
        u_free, high, low, hold = face.clamp_state(r, integ, vref)
        integ1, u1 = pi.carrier_step(integ, vref - r, 0.0)
        assert face.clamp(u_free) == pytest.approx(u1, rel=1e-14)
        assert (high, low) == (float(u_free > pi.u_max_V), float(u_free < pi.u_min_V))
        held, _ = pi.carrier_step(integ, vref - r, 1e-9)
        assert bool(hold) == (held == integ)
        assert face.limit(high) == (pi.u_max_V if high else pi.u_min_V)
