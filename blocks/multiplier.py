"""Analogue multiplier (blocks 8 and 13: modulator and demodulator)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Block


@dataclass
class Multiplier(Block):
    """``y = K_m a b`` (an AD633-style multiplier with scale ``K_m`` in 1/V).

    As a modulator, one factor (the PI output) varies slowly: the engines treat it as a
    scheduled gain. As a demodulator both factors are at the carrier: the envelope face
    :meth:`baseband` gives the mean of the product of two phasors.

    Parameters
    ----------
    k_per_V : float
        Multiplier scale factor K_m.
    """

    name: str = "multiplier"
    k_per_V: float = 1.0

    inputs = ("a", "b")
    outputs = ("out",)

    def baseband(self, A: complex, B: complex) -> float:
        """Mean of ``K_m Re(A e^{jwt}) Re(B e^{jwt})``: ``K_m Re(A conj(B)) / 2``.

        Parameters
        ----------
        A, B : complex
            Phasors of the two inputs.

        Returns
        -------
        float
        """
        return float(0.5 * self.k_per_V * np.real(A * np.conj(B)))

    def carrier_mean(self, a0, a1, b0, b1):
        """Mean of the product over a step, by the trapezoid rule (exact for its DC part).

        Parameters
        ----------
        a0, a1, b0, b1 : float or symbolic
            The two inputs at the start and end of the step.

        Returns
        -------
        float or symbolic
        """
        return 0.5 * self.k_per_V * (a0 * b0 + a1 * b1)
