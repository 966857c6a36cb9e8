"""Differential amplifier with finite bandwidth, offset and input noise (blocks 1, 11, 12)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import LinearBlock


@dataclass
class DifferentialAmplifier(LinearBlock):
    """Gain ``G`` with a single bandwidth pole at GBW/|G|, an output offset and input noise.

    ``H(s) = G / (1 + s/w_p)``, ``w_p = 2 pi GBW / |G|``; the phase lag at f is
    about ``|G| f / GBW`` (physics brief section 2).

    Parameters
    ----------
    gain : float
        Closed-loop gain (V/V, sign = polarity).
    gbw_Hz : float
        Op-amp gain-bandwidth product.
    offset_V : float
        Output-referred offset.
    input_noise_V_per_sqrtHz : float
        Input-referred white-noise density (one-sided); the engines inject it.
    """

    name: str = "diff_amp"
    gain: float = 1.0
    gbw_Hz: float = 10e6
    offset_V: float = 0.0
    input_noise_V_per_sqrtHz: float = 0.0

    inputs = ("in",)
    outputs = ("out",)

    @property
    def pole_rad_s(self) -> float:
        """Bandwidth pole w_p = 2 pi GBW / |G| in rad/s."""
        return 2 * np.pi * self.gbw_Hz / max(abs(self.gain), 1.0)

    states = ("V",)

    def abcd(self) -> tuple:
        """``x' = w_p (G u - x)``, ``y = x``.

        Returns
        -------
        tuple
            ``(A, B, C, D)``.
        """
        wp = self.pole_rad_s
        return [[-wp]], [[wp * self.gain]], [[1.0]], [[0.0]]

    def output_offset(self) -> np.ndarray:
        """The output offset in V.

        Returns
        -------
        ndarray
        """
        return np.array([self.offset_V])

    def phase_lag_rad(self, f_Hz: float) -> float:
        """Phase lag atan(w / w_p) at ``f_Hz``.

        Parameters
        ----------
        f_Hz : float

        Returns
        -------
        float
        """
        return float(np.arctan(2 * np.pi * f_Hz / self.pole_rad_s))
