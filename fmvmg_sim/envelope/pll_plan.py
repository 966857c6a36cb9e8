"""Numbers for the PLL drive's envelope step, and its kit for the roll-out.

The envelope step (:mod:`fmvmg_sim.envelope.pll_step`) runs through the carrier engine's roll-out
(:mod:`fmvmg_sim.carrier.engine`) with a step of at most :data:`PLL_ENVELOPE_STEP_S`: short enough
for the phase detector's low-pass and the phase loop, whose dynamics the envelope keeps, and
about 1,500 times longer than the carrier step.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from ..carrier.kits import StepKit, pll_channels
from ..carrier.plan import OperatingPlan
from ..carrier.pll_plan import pll_plan_common
from ..diagram import CORE_INPUTS
from ..pll_drive import PLLDrive, build_pll_drive
from .pll_step import PARAMS, PLL_ENVELOPE_MODEL, STATE
from .pll_table import PLLEnvelopeTable

#: Longest step of the PLL drive's envelope engine (s); an output interval is a whole number of steps.
PLL_ENVELOPE_STEP_S = 50e-6
#: Simulated seconds per compiled call of the PLL envelope (the carrier's half second is 10,000 envelope steps).
PLL_ENVELOPE_BATCH_S = 20.0
#: Frequency step of the central difference for the drive input's derivative in the frame's frequency (rad/s).
_DW = 2 * np.pi * 0.5


def rotating_input(A: np.ndarray, B: np.ndarray, omega: float, h_s: float) -> np.ndarray:
    """``int_0^h e^{A(h-s)} B e^{j omega s} ds``: a step's response to inputs ``B e^{j omega t}`` (Van Loan).

    Parameters
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
    omega : float
        rad/s.
    h_s : float

    Returns
    -------
    ndarray, complex, shape (n, m)
    """
    n, m = A.shape[0], B.shape[1]
    M = np.zeros((n + m, n + m), dtype=complex)
    M[:n, :n], M[:n, n:] = A, B
    M[n:, n:] = 1j * omega * np.eye(m)
    return expm(M * h_s)[:n, n:]


def make_pll_envelope_plan(pll: PLLDrive, h_s: float, noise_on: dict | None = None,
                           scale: np.ndarray | None = None) -> OperatingPlan:
    """Discretise the PLL drive's envelope for step ``h_s``.

    Parameters
    ----------
    pll : PLLDrive
    h_s : float
    noise_on : dict, optional
        Switches ``brownian`` and ``electronic`` (default: both on).
    scale : ndarray, optional
        Core state scaling, fixed across the operating points of a run.

    Returns
    -------
    OperatingPlan
    """
    plan, B, sig = pll_plan_common(pll, h_s, noise_on, scale, PARAMS)
    A0, w0 = plan.A_core, plan.steady.omega_rad_s
    b = B[:, -1:]
    G = rotating_input(A0, b, w0, h_s)[:, 0]
    G_w = (rotating_input(A0, b, w0 + _DW, h_s) - rotating_input(A0, b, w0 - _DW, h_s))[:, 0] / (2 * _DW)
    # white noise of one-sided PSD S: its complex envelope's parts each of PSD 2 S (twice the held real variance)
    Nc = np.exp(-1j * w0 * h_s) * rotating_input(A0, B[:, :len(CORE_INPUTS)], w0, h_s) * (np.sqrt(2.0) * sig)[None, :]
    plan.base.update(Phi=expm(A0 * h_s), Gr=G.real, Gi=G.imag, Gr_w=G_w.real, Gi_w=G_w.imag, Nr=Nc.real, Ni=Nc.imag)
    return plan


def pll_envelope_initial_state(plan: OperatingPlan, drive_displacement_m: float = 10e-9,
                               from_steady: bool = False) -> np.ndarray:
    """Initial envelope: a free drive oscillation of ``drive_displacement_m``, or the locked steady state.

    Only the positive-frequency part of the motion is set (``x = d``, ``v = j w d``), so the
    conjugate pole's fast term starts at zero.

    Parameters
    ----------
    plan : OperatingPlan
        From :func:`make_pll_envelope_plan`.
    drive_displacement_m : float, optional
    from_steady : bool, optional

    Returns
    -------
    ndarray
    """
    from .pll_step import detector_readings
    b, ss = plan.base, plan.steady
    n = plan.A_core.shape[0]
    x = dict(s_pd=[0.0, 0.0], integ_pll=0.0, v_tune=0.0, s_amp=[0.0, 0.0], integ=0.0, u=0.0, n=1.0,
             s_i=[0.0, 0.0], s_q=[0.0, 0.0], t=0.0, acc_rate=0.0, acc_quad=0.0, acc_amp=0.0, acc_u=0.0,
             acc_f=0.0, acc_tune=0.0)
    if from_steady:
        Z = np.linalg.solve(1j * ss.omega_rad_s * np.eye(n) - plan.A_core, plan.b_vac) * (
            b["k_mod"] * ss.agc_effort_V * b["vdac"])
        x.update(s_amp=[b["vref"], 0.0], u=ss.agc_effort_V, v_tune=ss.v_tune_V,
                 integ=ss.agc_effort_V / b["ki"] if b["ki"] > 0 else 0.0,
                 integ_pll=ss.v_tune_V / b["ki_pll"] if b["ki_pll"] > 0 else 0.0,
                 s_i=[ss.rate_V, 0.0], s_q=[ss.quadrature_V, 0.0])
    else:
        Z = np.zeros(n, dtype=complex)
        w = 2 * np.pi * b["f_free"]
        Z[0] = drive_displacement_m / plan.scale[0]
        Z[1] = 1j * w * drive_displacement_m / plan.scale[1]
    x["zr"], x["zi"] = Z.real, Z.imag
    p = PARAMS.pack(b)
    x["pd"], x["amp"], x["ri"], x["rq"] = (float(v) for v in detector_readings(Z.real, Z.imag, p))
    return STATE.pack(x)


def _envelope_step_s(scn, f_ref_Hz: float) -> float:
    dt_out = 1.0 / scn.settings["scenario"]["output_rate_Hz"]
    return dt_out / int(np.ceil(dt_out / PLL_ENVELOPE_STEP_S - 1e-9))


def _displacement(X, unit):
    L = STATE
    zr, zi = X[:, L.slices["zr"]], X[:, L.slices["zi"]]
    return np.hypot(zr[:, 0], zi[:, 0]) * unit.scale[0]


def _plan(device, die_C, board_C, h_s, noise_on, scale):
    return make_pll_envelope_plan(build_pll_drive(device, die_C, board_C), h_s, noise_on, scale)


def _param_rows(unit, k0: int, k1: int) -> np.ndarray:
    """The unit's parameter rows from its temperature table (built on first use)."""
    table = unit.__dict__.get("pll_table")
    if table is None:
        table = unit.pll_table = PLLEnvelopeTable(
            lambda die, board: _plan(unit.dev, die, board, unit.h, unit.noise_on, unit.scale),
            (unit.dev.content_key, unit.h, tuple(sorted(unit.noise_on.items())), unit.scale.tobytes()))
    s = slice(k0, k1)
    return table.rows(unit.keys[s], unit.board_keys[s], np.deg2rad(unit.rate_dps[s]), unit.slow.phase_rad[s],
                      unit.vref_f[s], unit.sig["quad_rel"][s])


#: The PLL drive's envelope engine, for the carrier engine's roll-out.
PLL_ENVELOPE = StepKit("envelope", PLL_ENVELOPE_MODEL, _plan, pll_envelope_initial_state, _envelope_step_s,
                       lambda X, M, unit: pll_channels(X, M, unit, STATE, _displacement), _param_rows,
                       batch_s=PLL_ENVELOPE_BATCH_S)

__all__ = ["PLL_ENVELOPE", "PLL_ENVELOPE_STEP_S", "make_pll_envelope_plan", "pll_envelope_initial_state",
           "rotating_input"]
