"""Gains of the PLL drive's loop filter: the linearised phase loop, robust over temperature and Q, checked in simulation.

The phase plant is the PLL drive's envelope model linearised at lock: in the oscillator's frame the
core's complex envelope obeys ``Z' = (A - j w) Z + b a``, so a frequency deviation ``dw`` enters as
``-j dw Z0`` (``Z0`` the locked envelope) and the phase detector reads ``Re(C_x Z e^{-j phi_t})``:
``G(s) = pd / dw``, exact to first order (drive amplifier, sense back-action and the modes' conjugate
poles included). Near lock ``G(s) ~ V / (s + 1/tau_d)`` (docs/model.md, PLL drive). The loop is
``L(s) = -G(s) P(s) 2 pi K_vco (K_p + K_i / s)`` with ``P`` the phase detector's low-pass (``G(0) < 0``:
the detector reads less as the frequency rises through the lock point).

:func:`design_pll_gains` places the crossover at a target bandwidth and the PI zero for a target phase
margin at the nominal point, then reports the crossover and margins at every temperature and Q of the
grid; :func:`check_pll_gains` starts the envelope engine off lock by a frequency error and compares
the frequency's recovery with the linear closed loop's.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from ..carrier.plan import OperatingPlan
from ..compiled import load_rollout
from ..device import Device
from ..envelope.pll_plan import PLL_ENVELOPE_STEP_S, make_pll_envelope_plan, pll_envelope_initial_state
from ..envelope.pll_step import PLL_ENVELOPE_MODEL, STATE
from ..pll_drive import PLLDrive, build_pll_drive

#: Temperatures of the robust grid (C).
PLL_GRID_C = (-40.0, -15.0, 10.0, 35.0, 60.0, 85.0)


def phase_plant(pll: PLLDrive) -> control.StateSpace:
    """Phase detector output per rad/s of oscillator frequency deviation, linearised at lock.

    Parameters
    ----------
    pll : PLLDrive

    Returns
    -------
    control.StateSpace
        SISO, input ``dw`` (rad/s), output ``pd`` (V); states the core's envelope (real and imaginary parts).
    """
    plan = make_pll_envelope_plan(pll, PLL_ENVELOPE_STEP_S, {"brownian": False, "electronic": False})
    return _plant_from_plan(plan)


def _plant_from_plan(plan: OperatingPlan) -> control.StateSpace:
    A, w0 = plan.A_core, plan.steady.omega_rad_s
    n = A.shape[0]
    b = plan.b_vac
    ss = plan.steady
    Z0 = np.linalg.solve(1j * w0 * np.eye(n) - A, b) * (plan.base["k_mod"] * ss.agc_effort_V * plan.base["vdac"])
    Af = np.block([[A, w0 * np.eye(n)], [-w0 * np.eye(n), A]])  # Z' = (A - j w0) Z in real form
    Bf = np.concatenate([Z0.imag, -Z0.real])[:, None]  # -j dw Z0
    pc, ps = plan.base["pd_cos"], plan.base["pd_sin"]
    Cf = np.concatenate([pc * plan.base["C_vx"], ps * plan.base["C_vx"]])[None, :]
    return control.ss(Af, Bf, Cf, [[0.0]])


def loop_transfer(pll: PLLDrive, kp: float, ki_per_s: float, plant: control.StateSpace | None = None):
    """The open phase loop ``L(s)``.

    Parameters
    ----------
    pll : PLLDrive
    kp, ki_per_s : float
        Loop-filter gains.
    plant : control.StateSpace, optional
        :func:`phase_plant` of ``pll``, if already built.

    Returns
    -------
    control.TransferFunction or control.StateSpace
    """
    G = phase_plant(pll) if plant is None else plant
    P = pll.pd_lpf.linear_model()
    pi = control.tf([kp, ki_per_s], [1.0, 0.0])
    # the detector reads less as the frequency rises through the lock point (G(0) < 0): with K_vco > 0 the loop
    # feeds back negatively, and L is written for the usual 1 + L = 0
    return control.series(G, control.ss(P.A, P.B, P.C, P.D), control.ss(pi), -2 * np.pi * pll.nco.k_vco_Hz_per_V)


def _freq(L, w):
    return np.array([complex(L(1j * x)) if not hasattr(L, "horner") else complex(L.horner(1j * x)[0, 0, 0])
                     for x in np.atleast_1d(w)])


def margins(L) -> dict:
    """Crossover frequency, phase margin and gain margin of an open loop (frequency sweep, bisection).

    Parameters
    ----------
    L : control LTI

    Returns
    -------
    dict
        ``crossover_Hz``, ``phase_margin_deg``, ``gain_margin_dB`` (inf when the phase never reaches -180 deg).
    """
    w = np.logspace(-1, 5, 1200) * 2 * np.pi
    H = control.frequency_response(L, w).complex.ravel()
    mag, ph = np.abs(H), np.unwrap(np.angle(H))
    k = np.flatnonzero((mag[:-1] >= 1) & (mag[1:] < 1))
    if not len(k):
        return {"crossover_Hz": float("nan"), "phase_margin_deg": float("nan"), "gain_margin_dB": float("nan")}
    k = k[0]
    f = np.log(mag[k]) / (np.log(mag[k]) - np.log(mag[k + 1]))
    wc = np.exp(np.log(w[k]) + f * (np.log(w[k + 1]) - np.log(w[k])))
    pc = np.angle(control.frequency_response(L, [wc]).complex.ravel()[0])
    pm = (np.rad2deg(np.pi + pc) + 180.0) % 360.0 - 180.0
    j = np.flatnonzero((ph[:-1] > -np.pi) & (ph[1:] <= -np.pi))
    gm = float(-20 * np.log10(mag[j[0]])) if len(j) else float("inf")
    return {"crossover_Hz": float(wc / (2 * np.pi)), "phase_margin_deg": float(pm), "gain_margin_dB": gm}


@dataclass
class PLLDesign:
    """Loop-filter gains and the loop's figures over the grid.

    Attributes
    ----------
    kp, ki_per_s : float
    target_bandwidth_Hz, target_phase_margin_deg : float
    rows : list of dict
        Per temperature and Q factor: crossover, phase and gain margins.
    """

    kp: float
    ki_per_s: float
    target_bandwidth_Hz: float
    target_phase_margin_deg: float
    rows: list

    def worst(self) -> dict:
        """Worst case over the grid: lowest phase margin, crossover range.

        Returns
        -------
        dict
        """
        pm = [r["phase_margin_deg"] for r in self.rows]
        fc = [r["crossover_Hz"] for r in self.rows]
        gm = [r["gain_margin_dB"] for r in self.rows]
        return {"phase_margin_deg_min": float(min(pm)), "crossover_Hz_min": float(min(fc)),
                "crossover_Hz_max": float(max(fc)), "gain_margin_dB_min": float(min(gm))}


def _pll_at(device: Device, T: float, q_factor: float) -> PLLDrive:
    if q_factor != 1.0:
        q = device.values["mechanics"]["q_drive"]
        device = device.with_overrides({"mechanics": {"q_drive": q * q_factor}}, "q tolerance")
    return build_pll_drive(device, T)


def design_pll_gains(device: Device, bandwidth_Hz: float = 30.0, phase_margin_deg: float = 60.0,
                     temperatures_C=PLL_GRID_C, q_factors=(0.8, 1.0, 1.2), log=None) -> PLLDesign:
    """Loop-filter gains for a crossover ``bandwidth_Hz`` and ``phase_margin_deg`` at the reference point.

    At the reference temperature the PI zero ``K_i/K_p = w_c tan(phi)`` takes the phase the plant and the
    detector's low-pass leave above the margin (``phi = 180 + arg(G P)(j w_c) - PM``), and ``K_p`` sets
    ``|L(j w_c)| = 1``. The loop is then evaluated on the grid.

    Parameters
    ----------
    device : Device
        With the PLL drive selected.
    bandwidth_Hz : float, optional
    phase_margin_deg : float, optional
    temperatures_C : sequence of float, optional
    q_factors : sequence of float, optional
        Drive-mode Q multipliers (the tolerance).
    log : callable, optional

    Returns
    -------
    PLLDesign

    Raises
    ------
    ValueError
        The plant and low-pass leave less phase than the margin asks at the bandwidth.
    """
    log = log or (lambda m: None)
    pll = build_pll_drive(device, device.reference_temperature_C)
    G = phase_plant(pll)
    wc = 2 * np.pi * bandwidth_Hz
    P = pll.pd_lpf.frequency_response(wc)[0, 0]
    GP = -complex(control.frequency_response(G, [wc]).complex.ravel()[0]) * P * 2 * np.pi * pll.nco.k_vco_Hz_per_V
    phi = np.pi + np.angle(GP) - np.deg2rad(phase_margin_deg)
    if not 0 < phi < np.pi / 2:
        raise ValueError(f"the phase loop has {np.rad2deg(np.pi + np.angle(GP)):.1f} deg at {bandwidth_Hz:g} Hz before "
                         f"the PI: a {phase_margin_deg:g} deg margin is out of reach there")
    r = np.tan(phi)  # Ki / (Kp wc)
    kp = 1.0 / (abs(GP) * abs(1 - 1j * r))
    ki = kp * wc * r
    rows = []
    for T in temperatures_C:
        for qf in q_factors:
            log(f"PLL loop at {T:g} C, Q x {qf:g}")
            p = _pll_at(device, T, qf)
            m = margins(loop_transfer(p, kp, ki))
            rows.append(dict(temperature_C=float(T), q_factor=float(qf), **m))
    return PLLDesign(float(kp), float(ki), float(bandwidth_Hz), float(phase_margin_deg), rows)


def check_pll_gains(device: Device, kp: float, ki_per_s: float, temperature_C: float = 25.0,
                    frequency_error_Hz: float = 1.0, duration_s: float = 0.3) -> dict:
    """The frequency's recovery from an error, in the envelope engine and in the linear closed loop.

    The loop starts locked but with the loop filter's integrator holding ``frequency_error_Hz`` too much
    (the oscillator off by that much); both the simulation (noise off) and the linearised loop recover.

    Parameters
    ----------
    device : Device
    kp, ki_per_s : float
    temperature_C : float, optional
    frequency_error_Hz : float, optional
    duration_s : float, optional

    Returns
    -------
    dict
        ``t_s``, ``simulated_Hz``, ``linear_Hz`` (the oscillator's frequency error), their settling times
        to 2 % of the error, and the largest difference relative to the error.
    """
    dev = device.with_overrides({"circuit": {"pll": {"kp": kp, "ki_per_s": ki_per_s}}}, "tune")
    pll = build_pll_drive(dev, temperature_C)
    h = PLL_ENVELOPE_STEP_S
    plan = make_pll_envelope_plan(pll, h, {"brownian": False, "electronic": False})
    x0 = pll_envelope_initial_state(plan, from_steady=True)
    dv = frequency_error_Hz / pll.nco.k_vco_Hz_per_V
    x0[STATE.slices["integ_pll"]] += dv / ki_per_s
    x0[STATE.slices["v_tune"]] += dv
    M = 4
    n = int(round(duration_s / (M * h)))
    roll = load_rollout(PLL_ENVELOPE_MODEL)
    P = plan.params(np.zeros(n))
    X = roll.units(x0[None], P[None], np.zeros((1, n * M, PLL_ENVELOPE_MODEL.n_inputs)), M)[0]
    t = (np.arange(n) + 1) * M * h
    sim = X[:, STATE.slices["acc_f"]][:, 0] / M - plan.steady.f_Hz
    # linear closed loop: the integrator's initial charge is a frequency error through the VCO
    G = _plant_from_plan(plan)
    Pl = pll.pd_lpf.linear_model()
    K = 2 * np.pi * pll.nco.k_vco_Hz_per_V
    ng = G.nstates
    A = np.zeros((ng + 3, ng + 3))
    # states: plant (ng), low-pass (2), integral of the low-passed pd (1); dw = K (kp y_lpf + ki integ)
    Ap, Bp, Cp = np.asarray(Pl.A), np.asarray(Pl.B), np.asarray(Pl.C)
    A[:ng, :ng] = G.A
    A[ng:ng + 2, :ng] = Bp @ G.C
    A[ng:ng + 2, ng:ng + 2] = Ap
    A[ng + 2, ng:ng + 2] = Cp[0]
    gain = K * np.concatenate([kp * Cp[0], [ki_per_s]])
    A[:ng, ng:] += np.asarray(G.B) @ gain[None, :]
    z0 = np.zeros(ng + 3)
    z0[-1] = dv / ki_per_s
    C = np.concatenate([np.zeros(ng), gain])[None, :] / (2 * np.pi)
    # the simulated samples are means over their output interval: the linear loop is read at their midpoints
    lin = control.initial_response(control.ss(A, np.zeros((ng + 3, 1)), C, [[0.0]]),
                                   T=np.arange(2 * n + 1) * (M * h / 2), X0=z0)
    lin_Hz = np.asarray(lin.outputs).ravel()[1::2]

    def settle(y):
        out = np.abs(y) > 0.02 * abs(frequency_error_Hz)
        return float(t[np.flatnonzero(out)[-1] + 1]) if out.any() and np.flatnonzero(out)[-1] + 1 < len(t) else (
            float("nan") if out.any() else 0.0)

    return {"t_s": t, "simulated_Hz": sim, "linear_Hz": lin_Hz, "settling_simulated_s": settle(sim),
            "settling_linear_s": settle(lin_Hz),
            "max_difference_rel": float(np.max(np.abs(sim - lin_Hz)) / abs(frequency_error_Hz))}


__all__ = ["phase_plant", "loop_transfer", "margins", "design_pll_gains", "check_pll_gains", "PLLDesign", "PLL_GRID_C"]
