"""Profiles evaluated the way the engines take them: limits, jumps, and the least-squares line over a step."""

import numpy as np
import pytest

from fmvmg_sim.effects import EffectSet
from fmvmg_sim.envelope.engine import BLOCK_SPAN_K, parameter_blocks
from fmvmg_sim.profiles import PiecewiseProfile
from fmvmg_sim.scenario import load_scenario

from .conftest import scenario_text

#: Holds, a drop to a tenth and back (steps), a ramp, and a sine.
PROFILE = PiecewiseProfile(np.array([0, 0.2, 0.2, 0.6, 0.6, 1.0, 2.0]), np.array([1, 1, 0.1, 0.1, 1, 1, 3.0]),
                           [(1.0, 1.5, 2.0, 7.0, 0.3)])


def _brute_line(p, a, b, n=200_000):
    """Least-squares line of ``p`` over [a, b] on a fine midpoint grid: its start and end values."""
    t = a + (np.arange(n) + 0.5) * (b - a) / n
    c = np.polyfit((t - a) / (b - a), p(t), 1)
    return c[1], c[0] + c[1]


def test_limits_and_jumps():
    assert PROFILE(0.2) == 0.1 and PROFILE.left_limit(0.2) == 1.0   # right-continuous; the value before
    assert PROFILE(0.4) == PROFILE.left_limit(0.4) == 0.1
    assert PROFILE.left_limit(1.2) == pytest.approx(PROFILE(1.2))      # continuous where there is no jump
    np.testing.assert_array_equal(PROFILE.jumps_s(), [0.2, 0.6])


@pytest.mark.parametrize("edges", [np.arange(41) * 0.05, np.array([0, 0.13, 0.27, 0.55, 0.61, 1.07, 1.2, 1.9, 2.5])])
def test_step_lines_are_the_least_squares_lines(edges):
    """On edges that hit the breakpoints: the profile's own limits (steps enter at their time); with breakpoints
    and sines inside a step: the line with the profile's mean and first moment."""
    start, end = PROFILE.step_lines(edges)
    for k in range(len(edges) - 1):
        s, e = _brute_line(PROFILE, edges[k], edges[k + 1])
        assert start[k] == pytest.approx(s, abs=2e-5) and end[k] == pytest.approx(e, abs=2e-5), k
    if len(edges) == 41:  # steps on the edges: exactly the limits
        k = int(np.argmin(np.abs(edges - 0.2)))
        assert end[k - 1] == 1.0 and start[k] == 0.1


def test_step_lines_of_a_constant_are_the_constant():
    p = PiecewiseProfile(np.array([0.0]), np.array([25.0]), [])
    s, e = p.step_lines(np.linspace(0, 10, 11))
    assert np.all(s == 25.0) and np.all(e == 25.0)


def _blocks(tmp_path, temperature, duration_s, rate_Hz, effects=""):
    path = tmp_path / "b.toml"
    path.write_text(scenario_text("b", duration_s, rate_Hz, temperature=temperature) + effects)
    scn = load_scenario(path, fidelity="envelope")
    fx = EffectSet(scn.effects)
    dt = 1.0 / rate_Hz
    n_out = int(np.ceil(duration_s / dt - 1e-9))
    t_fine = np.linspace(0.0, n_out * dt, min(n_out, 200_000))
    die = fx.die_temperature(t_fine, np.asarray(scn.temperature(t_fine), dtype=float))
    return parameter_blocks(scn, fx, dt, n_out, t_fine, die), n_out


def test_parameter_blocks_end_at_jumps_and_follow_fast_ramps(tmp_path):
    temp = ("start_C = -40.0\nsegments = [ { hold_s = 1.8 }, { step_to_C = 25.0 }, { hold_s = 0.3 }, "
            "{ ramp_to_C = 35.0, duration_s = 0.2 }, { hold_s = 1.0 } ]")
    (blocks, T), n_out = _blocks(tmp_path, temp, 3.3, 100.0)
    starts = [b[0] for b in blocks]
    assert sum(b[1] for b in blocks) == n_out and starts == sorted(starts)
    assert 180 in starts                                     # the jump at 1.8 s starts a block
    assert T[starts.index(180) - 1] == -40.0 and T[starts.index(180)] == 25.0
    ramp = [(b, t) for b, t in zip(blocks, T) if 210 <= b[0] < 230]
    assert len(ramp) == 20 and all(b[1] == 1 for b, _ in ramp)  # 10 K in 0.2 s: one block per output sample
    for (s, n), t in ramp:                                   # each at the ramp's mean temperature over it
        assert t == pytest.approx(25.0 + 10.0 * ((s + n / 2) / 100.0 - 2.1) / 0.2, abs=1e-9)
    assert max(b[1] for b in blocks) == 100                  # about a second elsewhere
    assert 10.0 / 20 > BLOCK_SPAN_K                          # (the ramp is faster than the blocks can follow)


def test_parameter_blocks_with_a_thermal_lag(tmp_path):
    temp = "start_C = 25.0\nsegments = [ { hold_s = 2.0 }, { step_to_C = 85.0 }, { hold_s = 8.0 } ]"
    (blocks, T), n_out = _blocks(tmp_path, temp, 10.0, 10.0, "[effects]\nthermal_lag = { tau_s = 30.0 }")
    assert sum(b[1] for b in blocks) == n_out
    # the die lags: no jump at 2 s, and the block temperatures rise smoothly towards 85 C
    after = np.array([t for b, t in zip(blocks, T) if b[0] >= 20])
    assert np.all(np.diff(after) > 0) and after[0] < 40.0 and after[-1] < 85.0
