"""The compiled roll-out: its noise generator, and the virtual-machine fallback against compiled code."""

import os

import numpy as np
import pytest
from scipy import stats

from fmvmg_sim.carrier.engine import run_carrier
from fmvmg_sim.carrier.step import CARRIER_MODEL
from fmvmg_sim.compiled import load_rollout
from fmvmg_sim.scenario import load_scenario


@pytest.fixture(scope="module")
def roll():
    r = load_rollout(CARRIER_MODEL, log=lambda m: None)
    if not r.compiled:
        pytest.skip("no C compiler on this machine")
    return r


def test_compiled_normals_are_standard_normal(roll):
    x = roll.normals(12345, 2_000_000)
    assert abs(x.mean()) < 3e-3
    assert x.var() == pytest.approx(1.0, abs=4e-3)
    assert stats.kurtosis(x, fisher=False) == pytest.approx(3.0, abs=0.03)
    assert np.mean(np.abs(x) > 3.0) == pytest.approx(2 * stats.norm.sf(3.0), rel=0.1)
    assert np.mean(np.abs(x) > 4.0) == pytest.approx(2 * stats.norm.sf(4.0), rel=0.35)  # the ziggurat's tail
    assert stats.kstest(x[:200_000], "norm").pvalue > 1e-3
    # no serial correlation
    assert abs(np.corrcoef(x[:-1], x[1:])[0, 1]) < 3e-3
    assert np.array_equal(roll.normals(7, 1000), roll.normals(7, 1000))
    assert not np.array_equal(roll.normals(7, 1000), roll.normals(8, 1000))


def test_virtual_machine_fallback_matches_compiled_code(make_scenario, monkeypatch):
    path = make_scenario(duration_s=0.004, output_rate_Hz=2000.0, state="rest")
    compiled = run_carrier(load_scenario(path), progress=False)
    import fmvmg_sim.compiled as comp
    monkeypatch.setenv("FMVMG_NO_COMPILE", "1")
    monkeypatch.setattr(comp, "_WARNED", False)
    msgs = []
    vm = run_carrier(load_scenario(path), progress=False, log=msgs.append)
    assert not vm.info["compiled"] and compiled.info["compiled"]
    assert any("virtual machine" in m for m in msgs)
    for k in ("drive_amplitude_V", "agc_effort_V", "quadrature_V"):
        assert np.allclose(vm[k], compiled[k], rtol=1e-9, atol=1e-12), k


def test_units_advanced_together_match_each_unit_alone():
    """Units in one vectorised call (own parameters, own seeds) give each unit's own roll-out bit for bit."""
    from fmvmg_sim.carrier.plan import initial_state, make_plan
    from fmvmg_sim.diagram import build_diagram
    from fmvmg_sim.device import load_device

    lanes = load_rollout(CARRIER_MODEL, log=lambda m: None, lanes=True)
    if not lanes.compiled:
        pytest.skip("no C compiler on this machine")
    single = load_rollout(CARRIER_MODEL, log=lambda m: None)
    dev = load_device("fmvmg_a")
    ref = build_diagram(dev, 25.0)
    h = 1.0 / (32 * ref.resonator.f_drive_Hz)
    plans = [make_plan(build_diagram(dev, T), h, None, ref.core_state_scale()) for T in (-40.0, 10.0, 25.0, 60.0, 85.0)]
    x0 = np.stack([initial_state(p, from_steady=True) for p in plans])
    K, M = 3, 200
    P = np.stack([p.params(np.deg2rad(np.linspace(0, 100 * u, K))) for u, p in enumerate(plans)])
    seeds = [11, 12, 13, 14, 2 ** 63 + 5]
    together = lanes.units(x0, P, None, M, seeds=seeds)
    assert together.shape == (5, K, x0.shape[1])
    for u in range(5):
        assert np.array_equal(together[u], single(x0[u], P[u], None, M, seed=seeds[u])), u
    # given inputs instead of drawn ones, and the same through the one-unit library
    W = np.random.default_rng(3).standard_normal((5, K * M, 4))
    given = lanes.units(x0, P, W, M)
    for u in range(5):
        assert np.array_equal(given[u], single(x0[u], P[u], W[u], M)), u
    assert np.array_equal(single.units(x0, P, W, M), given)
    # different temperatures really are different units
    assert not np.allclose(together[0], together[4])


def test_one_call_over_seed_blocks_equals_one_call_per_block(roll):
    """The engine hands many noise chunks (one seed each) to one call: the same numbers as a call per chunk."""
    from fmvmg_sim.carrier.plan import initial_state, make_plan
    from fmvmg_sim.diagram import build_diagram
    from fmvmg_sim.device import load_device

    dev = load_device("fmvmg_a")
    ref = build_diagram(dev, 25.0)
    plan = make_plan(ref, 1.0 / (32 * ref.resonator.f_drive_Hz), None, ref.core_state_scale())
    x = initial_state(plan, from_steady=True)
    P = plan.params(np.deg2rad(np.arange(7) * 10.0))
    seeds = [101, 202, 303]
    whole = roll.units(x[None], P[None], None, 150, seeds=[seeds], blocks_per_seed=3)[0]
    parts = []
    for j, s in enumerate(seeds):
        Xp = roll(x, P[3 * j:3 * j + 3], None, 150, seed=s)
        parts.append(Xp)
        x = roll.continue_from(Xp[-1])
    assert np.array_equal(whole, np.concatenate(parts))


def test_generated_c_matches_casadi_operation_by_operation(tmp_path, monkeypatch):
    """The C written from the expression graph gives CasADi's own numbers, NaN and infinity included."""
    import casadi as ca

    from fmvmg_sim.carrier.layout import Layout
    from fmvmg_sim.compiled import StepModel

    def step(x, p, w, ops):
        a, b = x[0], x[1]
        return [ops.fmin(a, b), ops.fmax(a, b), ops.if_else(a < b, a * b, a / b), ops.sqrt(ops.fabs(a)) - 2 * b,
                ops.if_else(a <= 0, 1.0, -3.5) + b * b, ca.sign(a) + ca.exp(b * 1e-3) + ops.cos(a) * ops.sin(b),
                ops.fmin(a, float("inf")) + p[0] * w[0]]

    model = StepModel("fmvmg_opcheck", Layout([(f"s{i}", ()) for i in range(7)]), Layout([("k", ())]), 1, step)
    monkeypatch.setenv("FMVMG_CACHE_DIR", str(tmp_path))
    roll = load_rollout(model, log=lambda m: None)
    if not roll.compiled:
        pytest.skip("no C compiler on this machine")
    f = model.casadi_function()
    vals = [-2.5, -1e-300, -0.0, 0.0, 1e-300, 0.75, 3.0, np.inf, -np.inf, np.nan]
    for a in vals:
        for b in vals:
            x0 = np.array([a, b, 0, 0, 0, 0, 0], dtype=float)
            got = roll(x0, np.array([[0.5]]), np.array([[2.0]]), 1)[0]
            want = np.asarray(f(x0, [0.5], [2.0])).ravel()
            assert np.array_equal(got, want, equal_nan=True), (a, b, got, want)


# --- refinement of flagged steps: a clamped first-order loop ----------------------------------------------
# x' = -a x + b u, u = clamp(k (r - x), 0, u_max): linear in each piece (free, clamped), discretised exactly per
# piece; a step that ends in another piece than it started in is flagged and redone in sub-steps.

from blocks.ops import numpy_ops  # noqa: E402
from fmvmg_sim.carrier.layout import Layout  # noqa: E402
from fmvmg_sim.compiled import Refinement, StepModel  # noqa: E402

_TOY_SUB = 16
_TOY_X = Layout([("x", ()), ("u", ()), ("refine", ())])
_TOY_P = Layout([(n, ()) for n in ("b", "k", "u_max", "ef", "gf", "eh", "gh", "efs", "gfs", "ehs", "ghs")])


def _toy_params(a=5.0, b=2.0, k=40.0, u_max=3.0, h=0.05):
    lam = a + b * k

    def disc(rate, hh):  # x+ = e x + g * (forcing / rate) ... as (decay, gain per unit of rate-normalised input)
        e = np.exp(-rate * hh)
        return e, (1.0 - e) / rate

    ef, gf = disc(lam, h)
    eh, gh = disc(a, h)
    efs, gfs = disc(lam, h / _TOY_SUB)
    ehs, ghs = disc(a, h / _TOY_SUB)
    return _TOY_P.pack(dict(b=b, k=k, u_max=u_max, ef=ef, gf=gf, eh=eh, gh=gh, efs=efs, gfs=gfs, ehs=ehs, ghs=ghs))


def _toy_advance(xs, p, r, sub, ops):
    P = _TOY_P.unpack
    x = xs[0]
    b, k, umax = P(p, "b"), P(p, "k"), P(p, "u_max")
    e_f, g_f, e_h, g_h = ((P(p, "efs"), P(p, "gfs"), P(p, "ehs"), P(p, "ghs")) if sub
                          else (P(p, "ef"), P(p, "gf"), P(p, "eh"), P(p, "gh")))
    u_free = k * (r - x)
    high = u_free > umax
    U = ops.if_else(high, umax, 0.0)
    clamped = 1.0 * high + 1.0 * (u_free < 0)
    free = e_f * x + g_f * b * k * r
    held = e_h * x + g_h * b * U
    x1 = ops.if_else(clamped > 0, held, free)
    u1f = k * (r - x1)
    clamped1 = 1.0 * (u1f > umax) + 1.0 * (u1f < 0)
    return x1, ops.fmin(ops.fmax(u1f, 0.0), umax), clamped, clamped1


def _toy_step(xs, p, w, ops):
    x1, u1, c0, c1 = _toy_advance(xs, p, w[0], False, ops)
    return [x1, u1, ops.if_else(ops.fabs(c1 - c0) > 0, 1.0, 0.0)]


def _toy_substep(xs, p, wj, ops):
    x1, u1, _, _ = _toy_advance(xs, p, wj[0], True, ops)
    return [x1, u1, 0.0]


TOY = StepModel("fmvmg_test_refine", _TOY_X, _TOY_P, 1, _toy_step,
                refine=Refinement(_toy_substep, _TOY_SUB, "refine"))


def _toy_exact(x0, r, p_kw, t_end):
    """The clamped loop from x0 under a constant reference, by tiny steps (the reference solution)."""
    a, b, k, umax = p_kw["a"], p_kw["b"], p_kw["k"], p_kw["u_max"]
    n = 200_000
    dt = t_end / n
    x = x0
    for _ in range(n):
        u = min(max(k * (r - x), 0.0), umax)
        x += dt * (-a * x + b * u)
    return x


def test_refined_steps_are_the_same_compiled_in_lanes_in_the_vm_and_in_numpy(monkeypatch):
    """A clamped loop whose set-point steps: the flagged steps are redone in sub-steps by every roll-out alike,
    and the refined result is the exact solution's to the sub-step's accuracy (the unrefined step is far off)."""
    single = load_rollout(TOY, log=lambda m: None)
    if not single.compiled:
        pytest.skip("no C compiler on this machine")
    lanes = load_rollout(TOY, log=lambda m: None, lanes=True)
    kw = dict(a=5.0, b=2.0, k=40.0, u_max=3.0, h=0.05)
    P = np.stack([_toy_params(**kw), _toy_params(**{**kw, "u_max": 2.0}), _toy_params(**{**kw, "k": 80.0})])
    K, M = 2, 10
    r = np.concatenate([np.full(5, 1.0), np.full(15, 0.1)])  # a step up (into the clamp), then down (below 0)
    W = np.repeat(r[None, :, None], 3, axis=0)
    x0 = np.zeros((3, 3))
    together = lanes.units(x0, P[:, None, :].repeat(K, axis=1), W, M)
    import fmvmg_sim.compiled as comp
    monkeypatch.setenv("FMVMG_NO_COMPILE", "1")
    monkeypatch.setattr(comp, "_WARNED", True)
    vm = load_rollout(TOY, log=lambda m: None)
    assert not vm.compiled
    for u in range(3):
        alone = single(x0[u], P[u][None].repeat(K, axis=0), W[u], M)
        assert np.array_equal(alone, together[u])
        np.testing.assert_allclose(vm(x0[u], P[u][None].repeat(K, axis=0), W[u], M), alone, rtol=1e-12, atol=1e-15)
        xs, flagged = x0[u].copy(), 0
        for s in range(K * M):
            flagged += _toy_step(list(xs), list(P[u]), [r[s]], numpy_ops)[2]
            xs = TOY.advance(xs, P[u], [r[s]])
            if s % M == M - 1:
                np.testing.assert_allclose(xs, alone[s // M], rtol=1e-12, atol=1e-15)
        assert 1 <= flagged <= 4  # the crossings only
    # against the exact solution: the first steps, into the clamp and out of it, refined or not
    n = 6  # the clamp is left at 0.29 s, within the sixth step
    x_ref = _toy_exact(0.0, 1.0, kw, n * kw["h"])
    xs = np.zeros(3)
    for s in range(n):
        xs = TOY.advance(xs, P[0], [1.0])
    x_plain = 0.0
    for s in range(n):
        x_plain = _toy_step([x_plain, 0.0, 0.0], list(P[0]), [1.0], numpy_ops)[0]
    assert abs(xs[0] - x_ref) < 0.2 * abs(x_plain - x_ref)   # measured 0.14: the sub-step's first-order error
    assert abs(xs[0] - x_ref) < 5e-4 * x_ref
