"""Full-wave rectifier (block 3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Block
from .ops import numpy_ops


@dataclass
class FullWaveRectifier(Block):
    """``y = G |u|`` (precision full-wave rectifier) with an output offset.

    Envelope face: for ``u = U cos(theta)`` the mean output is ``(2/pi) G U``
    (:meth:`describing_gain`). Carrier face: :meth:`carrier_mean` integrates ``|u|``
    exactly over a step under the assumption that ``u`` is locally a sinusoid at a
    known angular frequency, so the sampled engine has no aliasing bias from the kink
    at the zero crossing (a sampled ``|sin|`` at 32 points per cycle is off by up to 0.2 %).

    Parameters
    ----------
    gain : float
        Rectifier gain G.
    offset_V : float
        Output offset (a diode rectifier adds a temperature-dependent one).
    """

    name: str = "rectifier"
    gain: float = 1.0
    offset_V: float = 0.0

    inputs = ("in",)
    outputs = ("out",)

    def describing_gain(self) -> float:
        """Mean output per unit input amplitude of a sinusoid: ``2 G / pi``.

        Returns
        -------
        float
        """
        return 2.0 * self.gain / np.pi

    def second_harmonic_gain(self) -> float:
        """Amplitude of the output's second harmonic per unit input amplitude of a sinusoid: ``4 G / (3 pi)``.

        The ripple a full-wave rectifier leaves at twice the input frequency (|cos| has the
        Fourier series ``2/pi + (4/(3 pi)) cos 2 theta - ...``).

        Returns
        -------
        float
        """
        return self.gain * 4.0 / (3.0 * np.pi)

    @staticmethod
    def carrier_constants(omega_rad_s: float, h_s: float) -> tuple[float, float, float, float]:
        """Constants of :meth:`carrier_mean` for a step ``h_s`` at ``omega_rad_s`` (needs ``omega h < pi``).

        Parameters
        ----------
        omega_rad_s : float
            Local angular frequency of the input.
        h_s : float
            Step length.

        Returns
        -------
        tuple of float
            ``(cos wh, sin wh, tan(wh/2)/wh, 1/wh)``.
        """
        wh = omega_rad_s * h_s
        if not 0 < wh < np.pi:
            raise ValueError("the rectifier's carrier face needs 0 < omega h < pi (more than 2 steps per cycle)")
        return float(np.cos(wh)), float(np.sin(wh)), float(np.tan(wh / 2) / wh), float(1.0 / wh)

    def carrier_mean(self, v0, v1, consts, ops=numpy_ops):
        """Mean of ``G |v(t)| + offset`` over a step for a sinusoid through ``v0`` and ``v1``.

        The sinusoid at the angular frequency behind ``consts`` through ``v(0) = v0``
        and ``v(h) = v1`` is unique when ``omega h < pi``; its absolute value is
        integrated in closed form.

        Parameters
        ----------
        v0, v1 : float or symbolic
            Input at the start and end of the step.
        consts : tuple
            From :meth:`carrier_constants` (numbers or symbols).
        ops : object, optional
            Math backend.

        Returns
        -------
        float or symbolic
        """
        cw, sw, t2_over_wh, inv_wh = consts
        # no sign change: integral of a sinusoid through two points = (v0 + v1) tan(wh/2) / w
        mean_same = ops.fabs(v0 + v1) * t2_over_wh
        # sign change: write v = R sin(w (t - t_z)), flipped so that it rises through zero
        s = ops.if_else(v0 < 0, 1.0, -1.0)
        a0, a1 = s * v0, s * v1
        C = (a1 - a0 * cw) / sw   # R cos(w t_z)
        S = -a0                   # R sin(w t_z)
        R = ops.sqrt(C * C + S * S)
        mean_cross = (2 * R - C - C * cw - S * sw) * inv_wh
        return self.gain * ops.if_else(v0 * v1 >= 0, mean_same, mean_cross) + self.offset_V
