"""Numerically or voltage-controlled oscillator of a PLL drive (NCO/VCO)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import LinearBlock
from .ops import numpy_ops


@dataclass
class ControlledOscillator(LinearBlock):
    """An oscillator at ``f = f_free + K_vco v_tune``, with outputs ``cos(theta)`` and ``sin(theta)``.

    ``theta`` is the oscillator's phase; ``cos(theta)`` drives the combs (times the AGC output),
    ``sin(theta)`` is its quadrature output.

    Parameters
    ----------
    f_free_Hz : float
        Free-running frequency (tuning input at zero).
    k_vco_Hz_per_V : float
        Tuning gain (Hz per volt of the loop filter's output), positive.
    """

    name: str = "nco"
    f_free_Hz: float = 30740.0
    k_vco_Hz_per_V: float = 50.0

    inputs = ("v_tune",)
    outputs = ("theta",)
    states = ("phase",)

    def __post_init__(self) -> None:
        if not self.k_vco_Hz_per_V > 0:
            raise ValueError(f"k_vco_Hz_per_V must be positive, got {self.k_vco_Hz_per_V}")

    def abcd(self) -> tuple:
        """Linear face for the phase loop: the phase deviation integrates ``2 pi K_vco v_tune``.

        Returns
        -------
        tuple
            ``(A, B, C, D)`` of ``theta' = 2 pi K_vco v_tune`` (the free-running ramp removed).
        """
        return [[0.0]], [[2 * np.pi * self.k_vco_Hz_per_V]], [[1.0]], [[0.0]]

    def omega_rad_s(self, v_tune):
        """Angular frequency at tuning voltage ``v_tune`` (envelope face: the frame's frequency).

        Parameters
        ----------
        v_tune : float or symbolic
            Loop-filter output (V).

        Returns
        -------
        float or symbolic
            rad/s.
        """
        return 2 * np.pi * (self.f_free_Hz + self.k_vco_Hz_per_V * v_tune)

    def carrier_step(self, theta, v_tune, h_s, ops=numpy_ops):
        """Advance the phase over a step with the tuning voltage held, wrapped to [-pi, pi).

        Parameters
        ----------
        theta : float or symbolic
            Phase at the start of the step (rad, within [-pi, pi)).
        v_tune : float or symbolic
            Tuning voltage over the step.
        h_s : float
            Step length (shorter than one period).
        ops : object, optional
            Math backend.

        Returns
        -------
        tuple
            ``(theta_next, cos(theta_next), sin(theta_next))``.
        """
        th = theta + self.omega_rad_s(v_tune) * h_s
        th = ops.if_else(th >= np.pi, th - 2 * np.pi, th)
        return th, ops.cos(th), ops.sin(th)
