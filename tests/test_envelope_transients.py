"""The envelope engine through large transients, against the carrier engine and closed forms.

Clamped PI (a set-point dropped to a tenth and restored), the carrier normaliser's floor (start-up
from 10 nm), a temperature step, the sense mode's ringing after a rate step, and the clamped
steady state. Noise off throughout; config A.
"""

import numpy as np
import pytest
from scipy.linalg import expm

from fmvmg_sim.averaged import steady_state
from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.device import load_device
from fmvmg_sim.diagram import build_diagram
from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.scenario import load_scenario

from .conftest import scenario_text

DROP = "[vref]\nsegments = [ { hold_s = 0.2 }, { step_to_factor = 0.1 }, { hold_s = 0.4 }, { step_to_factor = 1.0 } ]\n"


def _run(path, fidelity, overrides=()):
    scn = load_scenario(path, fidelity=fidelity, overrides=list(overrides))
    return run_carrier(scn, progress=False) if fidelity == "carrier" else run_envelope(scn, progress=False)


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory):
    """Write a config-A scenario (noise off, steady start at 25 C unless told) with a given body."""
    root = tmp_path_factory.mktemp("transients")

    def make(name, body, duration_s, output_rate_Hz, state="steady", temperature="start_C = 25.0"):
        p = root / f"{name}.toml"
        p.write_text(scenario_text(name, duration_s, output_rate_Hz, state, temperature) + body)
        return p
    return make


@pytest.fixture(scope="module")
def setpoint_drop(scenario_file):
    """The AGC set-point dropped to a tenth at 0.2 s and restored at 0.6 s, 100 Hz output, default step."""
    path = scenario_file("drop", DROP, 1.0, 100.0)
    return _run(path, "carrier"), _run(path, "envelope")


def test_setpoint_drop_clamps_the_pi_inside_the_step(setpoint_drop):
    """The PI clamps at 0 V through the drop and at 8 V after the restore, reached and left within steps of
    10 ms: the drive amplitude estimate follows the carrier engine's (measured: 0.003 % through the drop,
    0.11 % in the first sample after the restore, 0.015 % after)."""
    c, e = setpoint_drop
    assert e.info["step_s"] == pytest.approx(0.01)
    t = e.time_s
    rel = np.abs(e["drive_amplitude_V"] / c["drive_amplitude_V"] - 1.0)
    assert np.max(rel[(t > 0.2) & (t <= 0.6)]) < 0.002
    assert np.max(rel[t > 0.6]) < 0.005
    assert np.max(rel[t > 0.7]) < 0.001
    # the effort: clamped at the limits in both engines, mean over each sample alike
    u_c, u_e = c["agc_effort_V"], e["agc_effort_V"]
    assert np.all(u_e[(t > 0.21) & (t < 0.45)] == 0.0) and np.all(u_c[(t > 0.21) & (t < 0.45)] == 0.0)
    assert np.max(np.abs(u_e - u_c)[t > 0.2]) < 0.02 * 8.0


def test_startup_through_the_normaliser_floor(scenario_file):
    """From 10 nm the carrier is the pickoff scaled up to Vdac only above the normaliser's floor; below it the
    drive force grows with the amplitude. Both engines model it: the time to 90 % amplitude agrees (measured
    26.99 ms carrier, 27.00 ms envelope at 100 Hz output; without the floor the envelope reached it in 22 ms)."""
    path = scenario_file("startup", "", 0.1, 100.0, state="rest")
    c, e = (_run(path, f, ["initial.drive_displacement_m=10e-9"]) for f in ("carrier", "envelope"))
    t = e.time_s
    ac, ae = c["drive_amplitude_V"], e["drive_amplitude_V"]
    grown = ac > 0.05 * 0.45
    assert np.max(np.abs(ae / ac - 1.0)[grown]) < 0.005

    def t90(res):
        a = res.internal["drive_displacement_amplitude_m"]
        k = int(np.flatnonzero(a >= 0.9 * a[-1])[0])
        return np.interp(0.9 * a[-1], a[k - 1:k + 1], res.time_s[k - 1:k + 1])
    assert t90(e) == pytest.approx(t90(c), abs=2e-4)
    assert t90(e) > 0.025  # 22 ms is what the envelope gave without the floor


def test_temperature_step_reaches_the_physics_on_time(scenario_file):
    """A temperature step at 0.5 s: the envelope's parameters change at the sample the record shows it, and the
    zero-rate output on each side is the carrier's."""
    temp = "start_C = -40.0\nsegments = [ { hold_s = 0.5 }, { step_to_C = 85.0 } ]"
    path = scenario_file("tstep", "", 1.0, 200.0, temperature=temp)
    c, e = _run(path, "carrier"), _run(path, "envelope")
    t = e.time_s
    k = int(np.flatnonzero(e["temperature_C"] == 85.0)[0])
    f = e["drive_frequency_Hz"]
    assert abs(f[k] - f[k - 1]) > 50.0 and np.all(np.abs(np.diff(f[:k])) < 0.05)  # the frequency moves with it
    for a, b in ((0.35, 0.5), (0.85, 1.0)):
        mc = (c.time_s > a) & (c.time_s <= b)
        me = (t > a) & (t <= b)
        bc, be = np.mean(c["rate_dps"][mc]), np.mean(e["rate_dps"][me])
        assert be == pytest.approx(bc, rel=0.01), (a, bc, be)
    # the 85 C bias (the averaged model's steady state there), not the -40 C one
    dev = load_scenario(path).device
    b85, b40 = (steady_state(build_diagram(dev, T)).rate_V / e.info["nominal_scale_factor_V_per_dps"] for T in (85.0, -40.0))
    assert abs(b85 - b40) > 1.0
    assert np.mean(e["rate_dps"][t > 0.85]) == pytest.approx(b85, rel=0.01)


def _sense_step_closed_form(dg, ss, t_s, rate_step_rad_s):
    """The rate output's response to a rate step from the exact second-order sense mode (quadrature off).

    ``m Y'' + (2 i w m + c) Y' + Z Y = F`` for the Coriolis force phasor ``F = -2 i w m_c W A`` from rest,
    through the sense amplifiers, the output low-pass (applied to Re and Im of the phasor) and the
    in-phase demodulation; each sample the mean over its interval.
    """
    r = dg.resonator
    w = ss.omega_rad_s
    m, c, k = r.m_sense_kg, r.c_sense_N_s_per_m, r.k_sense_N_per_m
    D, Z = 2j * w * m + c, k - m * w * w + 1j * w * c
    F = -2j * w * r.m_coriolis_kg * rate_step_rad_s * ss.amplitude_m
    kY = dg.sense_amps_response(w) * dg.sense_pickoff.gain_V_per_m
    lp = dg.output_lpf.linear_model()
    Ao, Bo = np.asarray(lp.A), np.asarray(lp.B)[:, 0] / dg.output_lpf.gain
    # real state: Y (re, im), Y' (re, im), LPF of Re V (2), LPF of Im V (2), integrals of the LPF outputs (2)
    cm = lambda z: np.array([[z.real, -z.imag], [z.imag, z.real]])  # noqa: E731
    A = np.zeros((10, 10))
    b = np.zeros(10)
    A[0:2, 2:4] = np.eye(2)
    A[2:4, 0:2] = -cm(Z / m)
    A[2:4, 2:4] = -cm(D / m)
    b[2:4] = [(F / m).real, (F / m).imag]
    for comp, rows in ((0, slice(4, 6)), (1, slice(6, 8))):
        A[rows, rows] = Ao
        A[rows, 0:2] = np.outer(Bo, cm(kY)[comp])
    A[8, 4], A[9, 6] = 1.0, 1.0
    Mx = np.zeros((11, 11))
    Mx[:10, :10], Mx[:10, 10] = A, b
    dt = t_s[1] - t_s[0]
    E = expm(Mx * dt)
    x = np.zeros(11)
    x[10] = 1.0
    out = []
    for _ in t_s:
        x0 = x.copy()
        x = E @ x
        V = np.array([x[8] - x0[8], x[9] - x0[9]]) / dt
        out.append(0.5 * dg.output_lpf.gain * dg.demodulator.k_per_V * (V[0] * ss.R_I.real + V[1] * ss.R_I.imag))
    return np.array(out)


def test_sense_ringing_is_the_exact_second_order_mode(scenario_file):
    """A 50 deg/s rate step rings at the 146 Hz split and decays with 2 m_s / c_s: the envelope's rate output
    follows the exact second-order sense mode's closed form within 1e-4 of the step (measured 5e-6; the
    first-order envelope, its pole at (w_s^2 - w^2)/(2 w), is off by 3 % of the step in the ringing)."""
    body = "[rate]\nsegments = [ { hold_s = 0.02 }, { step_to_dps = 50.0 } ]\n"
    path = scenario_file("ring", body, 0.1, 10000.0)
    over = ["device.mechanics.quadrature_rate_dps=0.0", "device.mechanics.damping_coupling_rate_dps=0.0"]
    scn = load_scenario(path, fidelity="envelope", overrides=over)
    e = run_envelope(scn, progress=False)
    dg = build_diagram(scn.device, 25.0)
    ss = steady_state(dg)
    t = e.time_s
    after = t > 0.02 + 1e-9
    sf = e.info["nominal_scale_factor_V_per_dps"]
    sim = (e["rate_V"][after] - e["rate_V"][~after][-1]) / sf
    exact = _sense_step_closed_form(dg, ss, t[after] - 0.02, np.deg2rad(50.0)) / sf
    assert np.max(np.abs(sim - exact)) < 1e-4 * 50.0
    # the closed form is sensitive to the pole: the first-order envelope's ringing is off by far more
    s1_first = -(dg.resonator.k_sense_N_per_m - dg.resonator.m_sense_kg * ss.omega_rad_s ** 2
                 + 1j * ss.omega_rad_s * dg.resonator.c_sense_N_s_per_m) / (
        2j * ss.omega_rad_s * dg.resonator.m_sense_kg + dg.resonator.c_sense_N_s_per_m)
    s1, _, _ = dg.resonator.envelope_mode("sense", ss.omega_rad_s)
    assert abs(s1_first.imag / s1.imag - 1) > 2e-3 and abs(s1_first.real / s1.real - 1) > 4e-3


@pytest.mark.parametrize("device", ["fmvmg_a", "fmvmg_b", "dualmass_004"])
def test_first_order_drive_envelope_is_within_its_bound(device):
    """The drive mode stays first order in the envelope: its amplitude's response to a force step is the
    exact second-order mode's within 2e-4 of the final amplitude (measured 1e-5 to 1e-4) for every device."""
    dg = build_diagram(load_device(device), 25.0)
    w = steady_state(dg).omega_rad_s
    r = dg.resonator
    m, c, k = r.m_drive_kg, r.c_drive_N_s_per_m, r.k_drive_N_per_m
    Z, D = k - m * w * w + 1j * w * c, 2j * w * m + c
    t = np.linspace(0.0, 5 * 2 * m / c, 2000)
    F = 1j  # in phase with the velocity, as the loop drives it
    # the second-order mode from rest: partial fractions of F / (s m (s - s1)(s - s2))
    s1, s2 = np.roots([m, D, Z])
    exact = F / m * (1 / (s1 * s2) + np.exp(s1 * t) / (s1 * (s1 - s2)) + np.exp(s2 * t) / (s2 * (s2 - s1)))
    first = F / Z * (1 - np.exp(-Z / D * t))
    assert np.max(np.abs(np.abs(first) - np.abs(exact))) < 2e-4 * abs(exact[-1])


def test_clamped_steady_state_in_both_engines(scenario_file):
    """With u_max below the effort the set-point needs, the PI stays at u_max and the amplitude settles where
    that effort holds it: the averaged steady state says where, and both engines get there from rest."""
    over = ["device.circuit.pi.u_max_V=0.5"]
    path = scenario_file("clamped", "", 1.6, 100.0, state="rest")
    scn = load_scenario(path, fidelity="envelope", overrides=over)
    dg = build_diagram(scn.device, 25.0)
    ss = steady_state(dg)
    free = steady_state(build_diagram(load_device("fmvmg_a"), 25.0))
    assert ss.agc_saturated and not free.agc_saturated
    assert ss.agc_effort_V == 0.5
    assert ss.amplitude_m == pytest.approx(free.amplitude_m * 0.5 / free.agc_effort_V, rel=1e-3)  # linear resonator
    for fid in ("envelope", "carrier"):
        res = _run(path, fid, over + ["initial.drive_displacement_m=1e-7"])
        tail = res.time_s > 1.5
        assert np.mean(res.internal["drive_displacement_amplitude_m"][tail]) == pytest.approx(ss.amplitude_m,
                                                                                             rel=2e-3), fid
        assert np.all(res["agc_effort_V"][tail] == pytest.approx(0.5)), fid
