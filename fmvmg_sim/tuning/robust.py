"""Robust PI gains for the drive amplitude loop: a CasADi NLP solved with IPOPT.

Problem (every plant from :mod:`.linear_loop`, i.e. from the diagram's blocks)::

    minimise    T                                   (worst-case settling time bound)
    over        Kp, Ki, T, and per scenario i the crossover frequencies w_c,i, w_180,i
    subject to, for every scenario i = (temperature, Q_d factor) and sample t_k of the
    closed-loop unit step response r_i(t_k) (exact discretisation, step h):
        |1 - r_i(t_k)| <= beta (1 + exp((T - t_k) / tau_e))       soft settling envelope
        r_i(t_k) <= 1 + overshoot_max
        u_min <= u0_i + 0.1 Vref_i * u_i(t_k) <= u_max            PI output for a 10 % step
        |L_i(j w_c,i)| = 1,   Re L_i(j w_c,i) >= -cos(PM_min)      phase margin
        Im L_i(j w_180,i) = 0, -10^(-GM_min/20) <= Re L_i(j w_180,i) <= 0,  w_180,i >= w_c,i

**Why settling time, and how it is made smooth.** A user tunes for settling time;
ITAE is smooth but weighs the whole error history and, for this loop, trades a slow
Q-mismatch tail for overshoot differently from what a user reads off a step. Settling
time itself is discontinuous in the gains (it jumps when an overshoot peak crosses the
band edge), so it is bounded by an envelope: ``T`` is an upper bound of the time after
which ``|e| <= beta`` (to within a few ``tau_e``: the envelope is ``beta (1 + e^{(T - t)/tau_e})``,
``beta`` for ``t >> T`` and huge for ``t << T``), and minimising the worst case over the
scenarios is the epigraph form above. It is evaluated as
``(e/beta)^2 sigmoid((t - T)/tau_e)^2 <= 1`` (with a stable softplus), which cannot overflow.
``beta`` is the design band, 1.5 % by default: 0.5 point
inside the 2 % band the results are judged by, so the optimum does not sit exactly on
the discontinuity (an overshoot peak touching the 2 % edge), where a model error of
0.1 % would double the measured settling time.

**Margins inside CasADi.** The loop gain's magnitude decreases monotonically (PI and
plant magnitudes both fall with frequency), so the gain crossover is unique: a variable
``w_c,i`` held on ``|L| = 1`` by an equality, and on the unit circle the phase margin is
``>= PM`` exactly when ``Re L >= -cos(PM)``. The phase crossover is a variable held on
``Im L = 0`` with ``Re L < 0`` (the -180 deg crossing above the gain crossover; started
from python-control's value). ``L(jw) = (Kp + Ki/(jw)) P(jw)`` is affine in the gains;
``P(jw) = C (jwI - A)^-1 B`` is evaluated symbolically from the plant's balanced
state-space model as a real 2n x 2n solve. The reported margins are recomputed with
python-control afterwards (:func:`fmvmg_sim.tuning.linear_loop.analyze_loop`).

**Output limit.** ``u(t) = u0 + dVref * u_unit(t)`` along the same discretised step
(``u_unit`` is the closed loop's Vref -> u response, which includes the proportional
kick ``Kp dVref`` at ``t = 0+``) must stay in ``[u_min, u_max]`` with ``u0`` from each
scenario's steady state (it grows as Q_d falls), so the loop stays linear for a 10 % step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import control
import numpy as np
import scipy.linalg

from ..device import Device
from .linear_loop import (LoopMetrics, PlantParameters, analyze_loop, build_loop, diagram_at, plant_parameters,
                          pole_zero_rule)


@dataclass
class RobustSpec:
    """What the robust gains must satisfy, and the discretisation of the NLP.

    Attributes
    ----------
    temperatures_C : tuple of float
        Temperature grid (default six points over -40..85 C).
    q_factors : tuple of float
        Q_d tolerance corners (multipliers of Q_d(T)).
    phase_margin_deg, gain_margin_db, overshoot_pct : float
        Limits.
    step_fraction : float
        Set-point step for the output-limit check (fraction of Vref).
    settling_band : float
        Band the results are judged by (2 %).
    design_band : float
        Band the optimiser settles into (guard inside ``settling_band``).
    horizon_s, step_s : float
        Length and (fine) sample interval of the discretised step responses.
    fine_until_s, coarse_step_s : float
        After ``fine_until_s`` the responses are sampled every ``coarse_step_s`` (a
        multiple of ``step_s``); the slow Q-mismatch tail needs no finer grid.
    envelope_tau_s : float
        Softness of the settling envelope.
    """

    temperatures_C: tuple = tuple(np.linspace(-40.0, 85.0, 6))
    q_factors: tuple = (0.8, 1.0, 1.2)
    phase_margin_deg: float = 60.0
    gain_margin_db: float = 10.0
    overshoot_pct: float = 5.0
    step_fraction: float = 0.1
    settling_band: float = 0.02
    design_band: float = 0.015
    horizon_s: float = 0.3
    step_s: float = 2e-4
    fine_until_s: float = 0.08
    coarse_step_s: float = 1e-3
    envelope_tau_s: float = 5e-4

    def time_grid(self) -> tuple[np.ndarray, list]:
        """Sample times of the discretised step responses: ``step_s`` up to ``fine_until_s``, then coarser.

        Returns
        -------
        tuple
            (times t_0 = 0 .. t_N, list of (step, count) segments)
        """
        n1 = int(round(min(self.fine_until_s, self.horizon_s) / self.step_s))
        segs = [(self.step_s, n1)]
        rest = self.horizon_s - n1 * self.step_s
        if rest > 1e-12:
            k = max(1, int(round(self.coarse_step_s / self.step_s)))
            segs.append((k * self.step_s, int(np.ceil(rest / (k * self.step_s) - 1e-9))))
        steps = np.concatenate([np.full(n, hh) for hh, n in segs])
        return np.concatenate([[0.0], np.cumsum(steps)]), segs

    def as_dict(self) -> dict:
        """JSON-ready dict.

        Returns
        -------
        dict
        """
        d = dict(self.__dict__)
        d["temperatures_C"] = [float(t) for t in self.temperatures_C]
        d["q_factors"] = [float(q) for q in self.q_factors]
        return d


@dataclass
class ScenarioPlant:
    """One corner of the robust problem: the plant-and-sensor model ``u -> r`` at (T, Q factor).

    Attributes
    ----------
    temperature_C, q_factor : float
    params : PlantParameters
    A, B, C : ndarray
        Balanced state-space matrices of ``u -> r``.
    """

    temperature_C: float
    q_factor: float
    params: PlantParameters
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray


@dataclass
class RobustResult:
    """Robust gains and their check with python-control over every scenario.

    Attributes
    ----------
    kp, ki_per_s : float
        The robust gains.
    settling_bound_s : float
        The NLP's objective (bound on the worst-case settling into the design band).
    solver_status : str
    solver_iterations : int
    wall_time_s : float
    start : tuple of float
        Initial (Kp, Ki).
    spec : RobustSpec
    metrics : list of LoopMetrics
        python-control analysis at every scenario.
    """

    kp: float
    ki_per_s: float
    settling_bound_s: float
    solver_status: str
    solver_iterations: int
    wall_time_s: float
    start: tuple
    spec: RobustSpec
    metrics: list = field(default_factory=list)

    @property
    def worst(self) -> dict:
        """Worst case over the scenarios (python-control figures).

        Returns
        -------
        dict
            ``settling_time_s`` (max), ``phase_margin_deg`` and ``gain_margin_db`` (min),
            ``overshoot_pct`` and ``u_peak_V`` (max).
        """
        return worst_case(self.metrics)

    def satisfied(self) -> dict:
        """Which constraints hold in the python-control check.

        Returns
        -------
        dict of str to bool
        """
        return check_constraints(self.metrics, self.spec)

    def as_dict(self) -> dict:
        """JSON-ready dict.

        Returns
        -------
        dict
        """
        return dict(kp=self.kp, ki_per_s=self.ki_per_s, settling_bound_s=self.settling_bound_s,
                    solver_status=self.solver_status, solver_iterations=self.solver_iterations,
                    wall_time_s=self.wall_time_s, start=list(self.start), spec=self.spec.as_dict(),
                    worst=self.worst, satisfied=self.satisfied(),
                    scenarios=[m.as_dict() for m in self.metrics])


def worst_case(metrics: list[LoopMetrics]) -> dict:
    """Worst-case figures over a list of loop analyses.

    Parameters
    ----------
    metrics : list of LoopMetrics

    Returns
    -------
    dict
    """
    return dict(settling_time_s=float(max(m.settling_time_s for m in metrics)),
                phase_margin_deg=float(min(m.phase_margin_deg for m in metrics)),
                gain_margin_db=float(min(m.gain_margin_db for m in metrics)),
                overshoot_pct=float(max(m.overshoot_pct for m in metrics)),
                u_peak_V=float(max(m.u_peak_V for m in metrics)))


def check_constraints(metrics: list[LoopMetrics], spec: RobustSpec, tol: float = 1e-3) -> dict:
    """Whether the python-control figures meet the spec (with a small numerical tolerance).

    Parameters
    ----------
    metrics : list of LoopMetrics
    spec : RobustSpec
    tol : float, optional
        Relative tolerance.

    Returns
    -------
    dict of str to bool
    """
    w = worst_case(metrics)
    u_max = min(m.params.u_max_V for m in metrics)
    return dict(phase_margin=w["phase_margin_deg"] >= spec.phase_margin_deg * (1 - tol),
                gain_margin=w["gain_margin_db"] >= spec.gain_margin_db * (1 - tol),
                overshoot=w["overshoot_pct"] <= spec.overshoot_pct * (1 + tol),
                output_limit=w["u_peak_V"] <= u_max * (1 + tol),
                settled=bool(np.isfinite(w["settling_time_s"])))


def scenario_plants(device: Device, spec: RobustSpec) -> list[ScenarioPlant]:
    """The balanced ``u -> r`` models at every (temperature, Q factor) of ``spec``.

    Parameters
    ----------
    device : Device
    spec : RobustSpec

    Returns
    -------
    list of ScenarioPlant
    """
    out = []
    for T in spec.temperatures_C:
        for qf in spec.q_factors:
            dg = diagram_at(device, float(T), float(qf))
            p = plant_parameters(dg)
            g = build_loop(dg, params=p).plant_and_sensor()
            A, B, C = (np.asarray(m, dtype=float) for m in (g.A, g.B, g.C))
            _, (sc, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
            A = A * sc[None, :] / sc[:, None]
            B = B / sc[:, None]
            C = C * sc[None, :]
            out.append(ScenarioPlant(float(T), float(qf), p, A, B, C))
    return out


def _expm_taylor(M, norm_bound: float, order: int = 10):
    """Symbolic matrix exponential by scaling and squaring with a Taylor series.

    Parameters
    ----------
    M : casadi.SX
        Square matrix.
    norm_bound : float
        An upper estimate of ``||M||`` over the search region (sets the squarings).
    order : int, optional

    Returns
    -------
    casadi.SX
    """
    s = max(0, int(np.ceil(np.log2(max(norm_bound, 1e-12) / 0.25))))
    Ms = M / (2.0 ** s)
    n = M.shape[0]
    E = ca.SX.eye(n)
    term = ca.SX.eye(n)
    for k in range(1, order + 1):
        term = ca.mtimes(term, Ms) / k
        E = E + term
    for _ in range(s):
        E = ca.mtimes(E, E)
    return E


def _plant_freq(A, B, C, w):
    """Real and imaginary parts of ``C (jw I - A)^-1 B`` for a symbolic ``w``."""
    n = A.shape[0]
    I = np.eye(n)
    M = ca.vertcat(ca.horzcat(ca.DM(-A), -w * ca.DM(I)), ca.horzcat(w * ca.DM(I), ca.DM(-A)))
    rhs = ca.DM(np.vstack([B, np.zeros_like(B)]))
    X = ca.solve(M, rhs)
    Cd = ca.DM(C)
    return ca.mtimes(Cd, X[:n, :]), ca.mtimes(Cd, X[n:, :])


#: Scales of the decision variables (the NLP works on O(1) numbers).
KP_SCALE, KI_SCALE, T_SCALE = 100.0, 1000.0, 0.01
#: Gains the symbolic matrix exponential is sized for.
KP_MAX, KI_MAX = 2000.0, 2e4
#: IPOPT Hessian: "exact" (CasADi AD) or "lbfgs".
HESSIAN = "lbfgs"  # the exact Hessian of this non-convex problem sends IPOPT astray


def _crossovers(sp: ScenarioPlant, kp: float, ki_per_s: float) -> tuple[float, float]:
    """Gain and phase crossover frequencies (rad/s) of the loop of ``sp`` by python-control (initial guesses)."""
    P = control.ss(sp.A, sp.B, sp.C, 0.0)
    pi = control.tf([kp, ki_per_s], [1.0, 0.0])
    _, _, wpc, wgc = control.margin(pi * P)
    wgc = float(wgc) if np.isfinite(wgc) else 1.0
    wpc = float(wpc) if np.isfinite(wpc) and wpc > wgc else 5.0 * wgc
    return wgc, wpc


def corner_plants(plants: list[ScenarioPlant]) -> list[ScenarioPlant]:
    """The scenarios at the extreme temperatures and Q factors (the presolve's subset).

    Parameters
    ----------
    plants : list of ScenarioPlant

    Returns
    -------
    list of ScenarioPlant
    """
    ts = {min(p.temperature_C for p in plants), max(p.temperature_C for p in plants)}
    qs = {min(p.q_factor for p in plants), max(p.q_factor for p in plants)}
    return [p for p in plants if p.temperature_C in ts and p.q_factor in qs]


def solve_nlp(plants: list[ScenarioPlant], spec: RobustSpec, start: tuple, max_iter: int = 300,
              verbose: bool = False) -> tuple[float, float, float, dict]:
    """Build and solve the robust NLP over ``plants`` from ``start`` = (Kp, Ki).

    Parameters
    ----------
    plants : list of ScenarioPlant
    spec : RobustSpec
    start : tuple of float
    max_iter : int, optional
    verbose : bool, optional
        IPOPT's own iteration log (stdout).

    Returns
    -------
    tuple
        (Kp, Ki, settling bound in s, IPOPT stats dict)
    """
    kp0, ki0 = float(start[0]), float(start[1])
    kp_s, ki_s, T_s = ca.SX.sym("kp_s"), ca.SX.sym("ki_s"), ca.SX.sym("T_s")
    kp, ki, Tset = KP_SCALE * kp_s, KI_SCALE * ki_s, T_SCALE * T_s
    n_sc = len(plants)
    wsc = [2 * np.pi * 200.0] * n_sc
    wc_s = ca.SX.sym("wc_s", n_sc)
    wp_s = ca.SX.sym("wp_s", n_sc)
    t_k, segments = spec.time_grid()
    N = len(t_k) - 1
    h = spec.step_s
    beta = spec.design_band
    tau_e = spec.envelope_tau_s
    # ---- time domain: exact discretisation of the closed loop, unrolled in SX
    g_time, lbg_time, ubg_time = [], [], []
    softplus = ca.fmax((Tset - ca.DM(t_k)) / tau_e, 0) + ca.log1p(ca.exp(-ca.fabs((Tset - ca.DM(t_k)) / tau_e)))
    window = ca.exp(-2 * softplus)     # sigmoid((t - T)/tau_e)^2: 0 well before T, 1 after it
    for i, sp in enumerate(plants):
        A, B, C = sp.A, sp.B, sp.C
        Acl = ca.SX.zeros(4, 4)
        Acl[:3, :3] = ca.DM(A) - kp * ca.DM(B @ C)
        Acl[:3, 3] = ki * ca.DM(B)
        Acl[3, :3] = -ca.DM(C)
        aug = ca.SX.zeros(5, 5)
        aug[:4, :4] = Acl * h
        aug[:4, 4] = ca.vertcat(kp * ca.DM(B), 1.0) * h
        # ||aug||_inf for gains up to KP_MAX, KI_MAX (beyond them the series stays accurate to ~1e-12)
        bound = h * (np.abs(A).sum(axis=1).max() + KP_MAX * np.abs(B @ C).sum(axis=1).max()
                     + (KI_MAX + KP_MAX) * np.abs(B).max() + np.abs(C).sum() + 1.0)
        E = _expm_taylor(aug, bound)
        Phi, Gam = E[:4, :4], E[:4, 4]
        C4 = ca.DM(np.hstack([C, [[0.0]]]))
        xk = ca.SX.zeros(4)
        r_list, xi_list = [ca.SX(0.0)], [ca.SX(0.0)]
        for hh, n in segments:
            m = int(round(hh / h))
            Phi_m, Gam_m = Phi, Gam
            for _ in range(m - 1):             # exact: the step input is constant
                Phi_m, Gam_m = ca.mtimes(Phi, Phi_m), ca.mtimes(Phi, Gam_m) + Gam
            for _ in range(n):
                xk = ca.mtimes(Phi_m, xk) + Gam_m
                r_list.append(ca.mtimes(C4, xk))
                xi_list.append(xk[3])
        r = ca.vertcat(*r_list)
        u_unit = kp * (1 - r) + ki * ca.vertcat(*xi_list)
        e = 1 - r
        g_time.append(e * e / beta ** 2 * window)
        lbg_time.append(-np.inf * np.ones(N + 1))
        ubg_time.append(np.ones(N + 1))
        g_time.append(r)
        lbg_time.append(-np.inf * np.ones(N + 1))
        ubg_time.append((1 + spec.overshoot_pct / 100) * np.ones(N + 1))
        dv = spec.step_fraction * sp.params.vref_V
        g_time.append(sp.params.agc_effort_V + dv * u_unit)
        lbg_time.append(sp.params.u_min_V * np.ones(N + 1))
        ubg_time.append(sp.params.u_max_V * np.ones(N + 1))
    # ---- frequency domain: crossover variables held on |L| = 1 and Im L = 0
    g_f, lbg_f, ubg_f = [], [], []
    cos_pm = np.cos(np.deg2rad(spec.phase_margin_deg))
    gm_lin = 10 ** (-spec.gain_margin_db / 20)
    for i, sp in enumerate(plants):
        for which, wv in (("c", wc_s[i] * wsc[i]), ("p", wp_s[i] * wsc[i])):
            Pr, Pi = _plant_freq(sp.A, sp.B, sp.C, wv)
            Lr = kp * Pr + ki / wv * Pi
            Li = kp * Pi - ki / wv * Pr
            if which == "c":
                g_f += [Lr * Lr + Li * Li, Lr]
                lbg_f += [1.0, -cos_pm]
                ubg_f += [1.0, np.inf]
            else:
                g_f += [Li, Lr]
                lbg_f += [0.0, -gm_lin]
                ubg_f += [0.0, 0.0]
        g_f.append(wp_s[i] - wc_s[i])
        lbg_f.append(0.0)
        ubg_f.append(np.inf)
    z = ca.vertcat(kp_s, ki_s, T_s, wc_s, wp_s)
    nlp = {"x": z, "f": T_s, "g": ca.vertcat(*g_time, *g_f)}
    opts = {"ipopt.print_level": 5 if verbose else 0, "print_time": False, "ipopt.sb": "yes",
            "ipopt.max_iter": max_iter,
            **({"ipopt.hessian_approximation": "limited-memory"} if HESSIAN == "lbfgs" else {}), "ipopt.tol": 1e-6,
            "ipopt.print_frequency_iter": 1,
            "ipopt.acceptable_tol": 1e-4, "ipopt.acceptable_iter": 5, "ipopt.constr_viol_tol": 1e-7}
    solver = ca.nlpsol("robust_pi", "ipopt", nlp, opts)
    cross = [_crossovers(sp, kp0, ki0) for sp in plants]
    wc0 = [wc / w for (wc, _), w in zip(cross, wsc)]
    wp0 = [wp / w for (_, wp), w in zip(cross, wsc)]
    T0 = float(np.clip(6.0 / min(wc for wc, _ in cross), 0.01, 0.9 * spec.horizon_s))
    z0 = np.concatenate([[kp0 / KP_SCALE, ki0 / KI_SCALE, T0 / T_SCALE], wc0, wp0])
    lbz = np.concatenate([[1e-3, 0.0, 0.0], 1e-3 * np.ones(n_sc), 1e-3 * np.ones(n_sc)])
    ubz = np.concatenate([[np.inf, np.inf, spec.horizon_s / T_SCALE], 50 * np.ones(n_sc), 50 * np.ones(n_sc)])
    sol = solver(x0=z0, lbx=lbz, ubx=ubz, lbg=np.concatenate([*lbg_time, lbg_f]),
                 ubg=np.concatenate([*ubg_time, ubg_f]))
    stats = solver.stats()
    zs = np.asarray(sol["x"]).ravel()
    return float(zs[0] * KP_SCALE), float(zs[1] * KI_SCALE), float(zs[2] * T_SCALE), stats


def tune_robust(device: Device, spec: RobustSpec | None = None, start: tuple | None = None,
                log=None, max_iter: int = 300, verbose: bool = False, presolve: bool = True) -> RobustResult:
    """Robust Kp, Ki over the temperature grid and Q_d tolerance of ``spec``.

    Parameters
    ----------
    device : Device
    spec : RobustSpec, optional
    start : tuple of float, optional
        Initial (Kp, Ki); default: the pole-zero-cancellation rule at the reference temperature.
    log : callable, optional
        One-line progress messages.
    max_iter : int, optional
        IPOPT iteration limit.
    verbose : bool, optional
        IPOPT's iteration log.
    presolve : bool, optional
        Solve on the corner scenarios first (four times fewer constraints) and start the
        full problem from there.

    Returns
    -------
    RobustResult

    Raises
    ------
    RuntimeError
        If IPOPT fails and the python-control check of its last point breaks the spec.
    """
    spec = spec or RobustSpec()
    log = log or (lambda m: None)
    wall0 = time.perf_counter()
    plants = scenario_plants(device, spec)
    if start is None:
        start = pole_zero_rule(device.reference_diagram)
    kp0, ki0 = float(start[0]), float(start[1])
    x0 = (kp0, ki0)
    iters = 0
    corners = corner_plants(plants)
    if presolve and len(corners) < len(plants):
        kp1, ki1, T1, st = solve_nlp(corners, spec, x0, max_iter, verbose)
        iters += int(st["iter_count"])
        log(f"robust tuning: presolve on {len(corners)} corner scenarios: IPOPT {st['return_status']} after "
            f"{st['iter_count']} iterations: Kp={kp1:.4g} Ki={ki1:.4g}, settling bound {T1 * 1e3:.2f} ms")
        if st["success"]:
            x0 = (kp1, ki1)
    kp_opt, ki_opt, T_opt, stats = solve_nlp(plants, spec, x0, max_iter, verbose)
    iters += int(stats["iter_count"])
    log(f"robust tuning: {len(plants)} scenarios: IPOPT {stats['return_status']} after {stats['iter_count']} "
        f"iterations: Kp={kp_opt:.4g} Ki={ki_opt:.4g}, settling bound {T_opt * 1e3:.2f} ms")
    metrics = [analyze_loop(diagram_at(device, sp.temperature_C, sp.q_factor), kp_opt, ki_opt, sp.q_factor,
                            sp.params, spec.step_fraction) for sp in plants]
    res = RobustResult(kp=kp_opt, ki_per_s=ki_opt, settling_bound_s=T_opt,
                       solver_status=str(stats["return_status"]), solver_iterations=iters,
                       wall_time_s=time.perf_counter() - wall0, start=(kp0, ki0), spec=spec, metrics=metrics)
    if not stats["success"] and not all(res.satisfied().values()):
        raise RuntimeError(f"robust tuning failed: IPOPT {stats['return_status']}; constraints {res.satisfied()}")
    return res
