"""The averaged model with a closed sense loop: force-to-rebalance and quadrature control.

Sixteen states join the model of :mod:`fmvmg_sim.envelope.model` (after its integral K):

* each loop's controller (:class:`blocks.RebalanceController`: the demodulation low-pass and the
  integrator, five states), driven by the sense-chain output demodulated with the nominal
  reference, ``e = (K_m / 2) Re(V_s conj(R))``: the demodulation commutes with the slowly varying
  envelope as it does for the output low-pass;
* the output low-pass (14) on each loop's effort and its integral over a sample.

The rate loop's force ``F = p_I K_fb k_m C u_I`` (``C`` the carrier phasor) and the tuning electrodes'
``F = -p_Q k_t V_t A_0`` (the drive amplitude at the operating point: the tuning stiffness times the
drive displacement, linearised where the AGC holds it) enter the sense mode as its force does: through
the slow part, the feedthrough ``d F`` to the pickoff and the back-action on the drive. The tuning
stiffness's own back-action on the drive (``-dk_q Y``, with ``Y`` held near zero by the loops) is left
out. The model stays linear in each piece, so the exact discretisation, the pieces and the refinement
are those of the open chain.
"""

from __future__ import annotations

import numpy as np

from blocks import RebalanceController

from ..averaged import carrier_phasors
from ..diagram import Diagram
from ..numerics.discretize import noise_covariance
from ..numerics.layout import Layout
from . import model as base
from .model import IA, IK, ISI, ISI2, ISR, ISR2, IYI, IYR, N, N_NOISE
from .step import _J, EnvelopeStep

NC = len(RebalanceController.states)
ICI = N
ICQ = ICI + NC
IO = ICQ + NC
IJO, IOQ = IO + 2, IO + 3
IJQ = IOQ + 2
N_R = IJQ + 1
_NOISY = [i for i in range(N_R) if i != IK]  # states with a noise input (all but K, as in the open model)


def _shape(shape: tuple) -> tuple:
    return tuple(N_R if d == N else (N_R - 1 if d == N_NOISE else d) for d in shape)


PARAMS_R = Layout([(name, _shape(shape)) for name, shape in base.PARAMS.fields]
                  + [("ftr", ()), ("qc", ()), ("g_fb", ())])


class SenseLoopExtension:
    """The closed sense loops' states and couplings, for :func:`fmvmg_sim.envelope.model.operating_params`."""

    def _parts(self, ctx: dict):
        dg = ctx["dg"]
        loop = dg.sense_loop
        ss = ctx["ss"]
        p_i, p_q = loop.polarities(dg, ctx["w"], ctx["A0"], ctx["C0"], ss.R_I, ss.R_Q)
        Kc = p_i * loop.force_per_V(ctx["C0"]) if loop.force_rebalance else 0.0
        Kv = -p_q * loop.electrodes.dk_dV_N_per_m_per_V * ctx["A0"] if loop.quadrature_control else 0.0
        return loop, complex(Kc), complex(Kv)

    def system(self, M, Bu, Bc, bu, ctx: dict) -> tuple:
        """One piece's matrices extended by the loops' states and couplings.

        Parameters
        ----------
        M, Bu, Bc, bu : ndarray
            The open chain's state matrix, first-order-hold inputs, constant and held AGC input.
        ctx : dict
            The operating point's phasors (see :func:`~fmvmg_sim.envelope.model.operating_params`).

        Returns
        -------
        tuple of ndarray
        """
        dg, Ao, Bo = ctx["dg"], ctx["Ao"], ctx["Bo"]
        loop, Kc, Kv = self._parts(ctx)
        M2, Bu2, Bc2, bu2 = (np.zeros((N_R, N_R)), np.zeros((N_R, Bu.shape[1])), np.zeros(N_R), np.zeros(N_R))
        M2[:N, :N], Bu2[:N], Bc2[:N], bu2[:N] = M, Bu, Bc, bu
        # the sense-chain output V_s as rows over the states and inputs, from the output low-pass's rows
        vs = []
        for i1, i2 in ((ISR, ISR2), (ISI, ISI2)):
            m = np.zeros(N_R)
            m[:N] = M[i2] - np.where(np.isin(np.arange(N), (i1, i2)), M[i2], 0.0)
            vs.append([m / Bo[1], Bu[i2] / Bo[1], Bc[i2] / Bo[1], bu[i2] / Bo[1]])
        C_ci = loop.controller.state_space_matrices()[2][0]
        C_cq = loop.quad_controller.state_space_matrices()[2][0]
        u_row, v_row = np.zeros(N_R), np.zeros(N_R)
        u_row[ICI:ICI + NC] = C_ci if loop.force_rebalance else 0.0
        v_row[ICQ:ICQ + NC] = C_cq if loop.quadrature_control else 0.0
        # the loops' force on the sense mode: its slow part, the drive's back-action and the pickoff
        for K, row in ((Kc, u_row), (Kv, v_row)):
            M2[IYR] += (ctx["rs"] * K).real * row
            M2[IYI] += (ctx["rs"] * K).imag * row
            M2[IA] += (ctx["kap0"] * ctx["ds"] * K).real * row
            ft = ctx["kY"] * ctx["ds"] * K
            for comp, (i1, i2) in enumerate(((ISR, ISR2), (ISI, ISI2))):
                part = ft.real if comp == 0 else ft.imag
                M2[i1:i2 + 1] += np.outer(Bo, part * row)
                vs[comp][0] = vs[comp][0] + part * row
        # the controllers on the demodulated sense output
        g_d = 0.5 * dg.demodulator.k_per_V
        for on, blk, i0, R in ((loop.force_rebalance, loop.controller, ICI, ctx["ss"].R_I),
                               (loop.quadrature_control, loop.quad_controller, ICQ, ctx["ss"].R_Q)):
            A_c, B_c, _, _ = blk.state_space_matrices()
            sl = slice(i0, i0 + NC)
            M2[sl, sl] = A_c
            if not on:
                continue
            b = B_c[:, 0] * g_d
            for k, X in enumerate((M2, Bu2, Bc2, bu2)):
                e = R.real * vs[0][k] + R.imag * vs[1][k]
                X[sl] += np.outer(b, e) if X.ndim == 2 else b * e
        # the output low-pass on each effort and its integral
        for i0, ij, row in ((IO, IJO, u_row), (IOQ, IJQ, v_row)):
            M2[i0:i0 + 2, i0:i0 + 2] = Ao
            M2[i0:i0 + 2] += np.outer(Bo, row)
            M2[ij, i0] = 1.0
        return M2, Bu2, Bc2, bu2

    def noise(self, M_free, Gn, q, h_s: float, ctx: dict) -> tuple:
        """The one-step noise covariance of the noisy states and its factor, the loops' controllers included.

        Parameters
        ----------
        M_free : ndarray
            The extended state matrix of the free piece.
        Gn : ndarray
            The open chain's noise gains (N x 6).
        q : ndarray
            The noises' intensities.
        h_s : float
        ctx : dict

        Returns
        -------
        tuple of ndarray
            ``(Q, L)``.
        """
        loop = ctx["dg"].sense_loop
        Bo = ctx["Bo"]
        G = np.zeros((N_R, Gn.shape[1]))
        G[:N] = Gn
        vs = (Gn[ISR2] / Bo[1], Gn[ISI2] / Bo[1])
        g_d = 0.5 * ctx["dg"].demodulator.k_per_V
        for on, blk, i0, R in ((loop.force_rebalance, loop.controller, ICI, ctx["ss"].R_I),
                               (loop.quadrature_control, loop.quad_controller, ICQ, ctx["ss"].R_Q)):
            if on:
                G[i0:i0 + NC] = np.outer(blk.state_space_matrices()[1][:, 0] * g_d, R.real * vs[0] + R.imag * vs[1])
        Qf = noise_covariance(M_free, G, np.diag(q), h_s)  # split and joined on a long step
        Q = Qf[np.ix_(_NOISY, _NOISY)]
        return Q, noise_factor(Q)

    def steady(self, x_ss: np.ndarray, ctx: dict) -> np.ndarray:
        """The open chain's steady state extended by the loops' (their efforts held by the integrators).

        Parameters
        ----------
        x_ss : ndarray
            The open model's steady state (with the loops' force in ``Y`` and ``V_s``).
        ctx : dict

        Returns
        -------
        ndarray
        """
        return _extend_steady(ctx["dg"], x_ss, ctx["ss"], ctx["C0"], ctx["A0"], ctx["w"], ctx["ds"])


def _extend_steady(dg: Diagram, x_ss: np.ndarray, ss, C0: complex, A0: float, w: float, ds: complex) -> np.ndarray:
    loop = dg.sense_loop
    p_i, p_q = loop.polarities(dg, w, A0, C0, ss.R_I, ss.R_Q)
    k_out = dg.output_lpf.gain
    u = ss.rate_V / k_out if loop.force_rebalance else 0.0
    v = ss.quadrature_V / k_out if loop.quadrature_control else 0.0
    F = p_i * loop.force_per_V(C0) * u - p_q * loop.electrodes.dk_dV_N_per_m_per_V * A0 * v
    x = np.zeros(N_R)
    x[:N] = x_ss
    x[IYR] -= (ds * F).real  # the slow part: less the loops' force's feedthrough
    x[IYI] -= (ds * F).imag
    x[ICI:ICI + NC] = loop.controller.state_for_output(u)
    x[ICQ:ICQ + NC] = loop.quad_controller.state_for_output(v)
    x[IO], x[IOQ] = u, v
    return x


def _psd_sqrt(Q: np.ndarray) -> np.ndarray:
    """Square roots ``L L^T = Q`` of a stack of covariances, balanced by their standard deviations, with the
    eigenvalues rounding has pushed below zero clipped: the loops' fast controller states are almost
    deterministic functions of the slow ones over a long step, so the covariance is singular to rounding
    and a Cholesky factor does not exist."""
    Q = 0.5 * (Q + np.swapaxes(Q, 1, 2))
    d = np.sqrt(np.clip(np.einsum("kii->ki", Q), 0.0, None))
    safe = np.where(d > 0, d, 1.0)
    lam, V = np.linalg.eigh(Q / (safe[:, :, None] * safe[:, None, :]))
    return (d[:, :, None] * V) * np.sqrt(np.clip(lam, 0.0, None))[:, None, :]


def noise_factor(Q: np.ndarray) -> np.ndarray:
    """The step's noise factor from the covariance of the noisy states (stacked or not), a zero row for K.

    Parameters
    ----------
    Q : ndarray, shape (..., N_R - 1, N_R - 1)

    Returns
    -------
    ndarray, shape (..., N_R, N_R - 1)
    """
    Q = np.asarray(Q)
    Lq = _psd_sqrt(Q.reshape(-1, N_R - 1, N_R - 1))
    L = np.zeros((len(Lq), N_R, N_R - 1))
    L[:, _NOISY] = Lq
    return L.reshape(Q.shape[:-2] + (N_R, N_R - 1))


def operating_params(dg: Diagram, h_s: float, noise_on: dict) -> dict:
    """:func:`fmvmg_sim.envelope.model.operating_params` with the closed sense loops.

    Parameters
    ----------
    dg : Diagram
    h_s : float
    noise_on : dict

    Returns
    -------
    dict
        Fields of :data:`PARAMS_R` and ``steady``, ``x_steady``, ``Q``.
    """
    out = base.operating_params(dg, h_s, noise_on, extension=SenseLoopExtension())
    loop = dg.sense_loop
    out.update(ftr=float(loop.force_rebalance), qc=float(loop.quadrature_control), g_fb=dg.output_lpf.gain)
    return out


def steady_vector(dg: Diagram, rate_rad_s: float = 0.0, vref_factor: float = 1.0) -> tuple[np.ndarray, object]:
    """:func:`fmvmg_sim.envelope.model.steady_vector` with the closed sense loops' states.

    Parameters
    ----------
    dg : Diagram
    rate_rad_s : float, optional
    vref_factor : float, optional

    Returns
    -------
    tuple
        The state (:data:`N_R` values) and the steady state.
    """
    x, ss = base.steady_vector(dg, rate_rad_s, vref_factor)
    w, A = ss.omega_rad_s, ss.amplitude_m
    Hx, Hps = dg.drive_chain_response(w), dg.phase_shifter_response(w)
    C0, _, _ = carrier_phasors(dg, Hx * A, Hx * Hps * A)
    _, _, ds = dg.resonator.envelope_mode("sense", w)
    return _extend_steady(dg, x, ss, C0, A, w, ds), ss


class RebalanceStep(EnvelopeStep):
    """The averaged model's step with the closed sense loops: the outputs read from their efforts."""

    def channels(self, p, x1, inv_t, rate_V, quad_V, ops):
        """``rate_V`` from the rate loop's effort, ``quadrature_V`` from the quadrature loop's, when closed.

        Parameters
        ----------
        p, x1 : sequence
        inv_t : float or symbolic
        rate_V, quad_V : float or symbolic
            The open chain's demodulated outputs.
        ops : object

        Returns
        -------
        tuple
        """
        P = self.params.unpack
        ftr, qc, g = P(p, "ftr"), P(p, "qc"), P(p, "g_fb")
        return (ftr * g * x1[IJO] * inv_t + (1 - ftr) * rate_V, qc * g * x1[IJQ] * inv_t + (1 - qc) * quad_V)


REBALANCE_STEP = RebalanceStep(N_R, PARAMS_R, _J + (IJO, IJQ))
#: The averaged model with closed sense loops as a compilable model.
ENVELOPE_REBALANCE_MODEL = REBALANCE_STEP.model("fmvmg_envelope_rebalance")

__all__ = ["N_R", "PARAMS_R", "SenseLoopExtension", "operating_params", "steady_vector", "noise_factor",
           "RebalanceStep", "ENVELOPE_REBALANCE_MODEL"]
