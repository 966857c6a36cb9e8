"""Low-pass filters (blocks 4 and 14): first and second order."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import LinearBlock


@dataclass
class LowPass1(LinearBlock):
    """First-order low-pass ``K / (1 + s / w_c)``.

    Parameters
    ----------
    f_c_Hz : float
        Corner frequency.
    gain : float
        DC gain.
    """

    name: str = "lpf1"
    f_c_Hz: float = 100.0
    gain: float = 1.0

    inputs = ("in",)
    outputs = ("out",)

    states = ("V",)

    def abcd(self) -> tuple:
        """``x' = w_c (K u - x)``, ``y = x``.

        Returns
        -------
        tuple
            ``(A, B, C, D)``.
        """
        wc = 2 * np.pi * self.f_c_Hz
        return [[-wc]], [[wc * self.gain]], [[1.0]], [[0.0]]


@dataclass
class LowPass2(LinearBlock):
    """Second-order low-pass ``K w_c^2 / (s^2 + (w_c/q) s + w_c^2)`` (Butterworth for q = 1/sqrt 2).

    Parameters
    ----------
    f_c_Hz : float
        Corner (natural) frequency.
    gain : float
        DC gain.
    q : float
        Pole quality factor.
    """

    name: str = "lpf2"
    f_c_Hz: float = 100.0
    gain: float = 1.0
    q: float = 1 / np.sqrt(2)

    inputs = ("in",)
    outputs = ("out",)

    states = ("V", "dV")

    def abcd(self) -> tuple:
        """Controllable canonical form with states (y, y'/w_c).

        Returns
        -------
        tuple
            ``(A, B, C, D)``.
        """
        wc = 2 * np.pi * self.f_c_Hz
        A = [[0.0, wc], [-wc, -wc / self.q]]
        B = [[0.0], [wc * self.gain]]
        return A, B, [[1.0, 0.0]], [[0.0]]

    def settling_time_s(self, tol: float = 0.02) -> float:
        """Approximate settling time ``-ln(tol) / (zeta w_c)`` (for tuning heuristics).

        Parameters
        ----------
        tol : float, optional

        Returns
        -------
        float
        """
        wc = 2 * np.pi * self.f_c_Hz
        return float(-np.log(tol) / (wc / (2 * self.q)))
