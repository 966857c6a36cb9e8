"""Exact discretisation of linear systems (matrix exponentials, Van Loan's block trick)."""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm


def zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation: ``Phi = e^{A h}``, ``Gamma = int_0^h e^{A s} ds B``.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
    h : float
        Step length in s.

    Returns
    -------
    tuple of ndarray
        (Phi, Gamma)
    """
    n, m = A.shape[0], B.shape[1]
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    E = expm(M * h)
    return E[:n, :n], E[:n, n:]


def expm_derivative(A: np.ndarray, dA: np.ndarray, h: float) -> np.ndarray:
    """Directional derivative of ``e^{A h}`` along ``dA``: ``int_0^h e^{A(h-s)} dA e^{A s} ds``.

    With ``A(p) = A + p dA`` this gives ``e^{A(p) h} = e^{A h} + p * result + O(p^2)``.

    Parameters
    ----------
    A, dA : ndarray, shape (n, n)
    h : float

    Returns
    -------
    ndarray
    """
    n = A.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = A, dA, A
    return expm(M * h)[:n, n:]


def foh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact first-order-hold discretisation (input linear between samples).

    ``x_{k+1} = Phi x_k + G0 u_k + G1 u_{k+1}``.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
    h : float

    Returns
    -------
    tuple of ndarray
        (Phi, G0, G1)
    """
    n, m = A.shape[0], B.shape[1]
    M = np.zeros((n + 2 * m, n + 2 * m))
    M[:n, :n] = A * h
    M[:n, n:n + m] = B * h
    M[n:n + m, n + m:] = np.eye(m)
    E = expm(M)
    Phi, P0, P1 = E[:n, :n], E[:n, n:n + m], E[:n, n + m:]
    # P0 = int_0^h e^{A(h-s)} B ds ; P1 = int_0^h e^{A(h-s)} B (s/h) ds
    return Phi, P0 - P1, P1


#: Largest ``a h`` (decay rate times step) :func:`noise_covariance` takes in one Van Loan exponential:
#: its cancellation then costs at most ``e^{2 a h}`` machine epsilons, below 1e-6 relative.
VAN_LOAN_MAX_DECAY = 0.5 * np.log(1e-6 / np.finfo(float).eps)


def noise_covariance(A: np.ndarray, G: np.ndarray, Qc: np.ndarray, h: float) -> np.ndarray:
    """Covariance added over one step by white noise ``G w``, ``E[w w^T] = Qc delta``: ``int e^{As} G Qc G^T e^{A^T s} ds``.

    Van Loan's block exponential, whose off-diagonal block grows as ``e^{a h}`` (``a`` the fastest decay
    rate of ``A``) before the product with ``e^{A h}`` cancels it: a long step on a stiff system loses
    ``e^{2 a h}`` in relative precision (and overflows beyond ``a h`` of about 350). The step is therefore
    split into ``2^k`` equal parts with ``a h / 2^k`` at most :data:`VAN_LOAN_MAX_DECAY` (a relative error
    below 1e-6), and the parts are joined exactly: ``Q(2t) = Q(t) + Phi(t) Q(t) Phi(t)^T``.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    G : ndarray, shape (n, m)
    Qc : ndarray, shape (m, m)
        Two-sided intensity (one-sided PSD / 2).
    h : float

    Returns
    -------
    ndarray, shape (n, n)
    """
    n = A.shape[0]
    decay = float(np.max(-np.linalg.eigvals(A).real, initial=0.0)) * h
    k = int(np.ceil(np.log2(decay / VAN_LOAN_MAX_DECAY))) if decay > VAN_LOAN_MAX_DECAY else 0
    t = h / 2.0 ** k
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = G @ Qc @ G.T
    M[n:, n:] = A.T
    E = expm(M * t)
    Phi = E[n:, n:].T
    Q = Phi @ E[:n, n:]
    for _ in range(k):
        Q = Q + Phi @ Q @ Phi.T
        Phi = Phi @ Phi
    return 0.5 * (Q + Q.T)


def covariance_sqrt(Q: np.ndarray) -> np.ndarray:
    """A square root ``L`` with ``L L^T = Q`` for a symmetric positive semi-definite ``Q``.

    Parameters
    ----------
    Q : ndarray

    Returns
    -------
    ndarray
    """
    w, V = np.linalg.eigh(Q)
    return V * np.sqrt(np.clip(w, 0.0, None))[None, :]


def noise_factor(A: np.ndarray, G: np.ndarray, Qc: np.ndarray, h: float) -> np.ndarray:
    """Lower-triangular ``L`` with ``L L^T`` the one-step noise covariance (see :func:`noise_covariance`).

    States the noise cannot reach (structurally, through the non-zero entries of ``A``)
    get exactly zero rows; the reachable block is balanced by its own standard
    deviations before the Cholesky factorisation, so states of very different units
    (metres and volts) are factored accurately. The factor is unique and smooth in the
    parameters, so factors at neighbouring temperatures can be interpolated.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    G : ndarray, shape (n, m)
    Qc : ndarray, shape (m, m)
        Two-sided intensity.
    h : float

    Returns
    -------
    ndarray, shape (n, n)
    """
    n = A.shape[0]
    active = np.diag(Qc) > 0
    reach = np.any(G[:, active] != 0, axis=1) if active.any() else np.zeros(n, dtype=bool)
    while True:
        grown = reach | np.any((A[:, reach] != 0), axis=1)
        if np.array_equal(grown, reach):
            break
        reach = grown
    L = np.zeros((n, n))
    if not reach.any():
        return L
    R = np.flatnonzero(reach)
    Ar, Gr = A[np.ix_(R, R)], G[R]
    Q1 = noise_covariance(Ar, Gr, Qc, h)
    d = np.sqrt(np.clip(np.diag(Q1), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    As, Gs = Ar * (d[None, :] / d[:, None]), Gr / d[:, None]
    Qs = noise_covariance(As, Gs, Qc, h)
    try:
        Ls = np.linalg.cholesky(Qs + 1e-13 * np.eye(len(R)))
    except np.linalg.LinAlgError:  # numerically rank-deficient: triangular factor of the PSD square root
        w, V = np.linalg.eigh(0.5 * (Qs + Qs.T))
        root = V * np.sqrt(np.clip(w, 0.0, None))[None, :]
        r = np.linalg.qr(root.T, mode="r")
        Ls = r.T * np.where(np.diag(r) < 0, -1.0, 1.0)[None, :]
    L[np.ix_(R, R)] = d[:, None] * Ls
    return L


def batched_factor(Q: np.ndarray, rel_jitter: float = 1e-10) -> np.ndarray:
    """Lower-triangular factors of a stack of covariances ``Q[k]`` (balanced, jittered Cholesky).

    Each covariance is scaled by its own standard deviations, given a relative jitter
    (a covariance error of ``rel_jitter``) and factored; states without noise get zero rows.

    Parameters
    ----------
    Q : ndarray, shape (k, n, n)
    rel_jitter : float, optional

    Returns
    -------
    ndarray, shape (k, n, n)
    """
    Q = 0.5 * (Q + np.swapaxes(Q, 1, 2))
    d = np.sqrt(np.clip(np.einsum("kii->ki", Q), 0.0, None))
    on = d > 0
    safe = np.where(on, d, 1.0)
    Qn = Q / (safe[:, :, None] * safe[:, None, :])
    Qn = np.where(on[:, :, None] & on[:, None, :], Qn, 0.0)
    n = Q.shape[1]
    Lc = np.linalg.cholesky(Qn + (rel_jitter + np.where(on, 0.0, 1.0))[:, :, None] * np.eye(n)[None])
    return np.where(on[:, :, None], d[:, :, None] * Lc, 0.0)
