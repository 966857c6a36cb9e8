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
