"""The 90-degree phase shifter (block 2) as a real circuit: an inverting first-order RC all-pass.

``H(s) = K (s RC - 1) / (s RC + 1)``: unit magnitude, phase lead ``pi - 2 atan(w RC)``,
exactly +90 degrees at ``w RC = 1``. Its phase moves with frequency
(d phase / d ln f = -1 rad at the design point) and with temperature through
R(T) C(T), so a drifting drive frequency gives a real phase error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import LinearBlock


@dataclass
class AllPassPhaseShifter(LinearBlock):
    """First-order RC all-pass, inverting, giving +90 degrees at ``1/(2 pi RC)``.

    Parameters
    ----------
    rc_s : float
        Time constant RC at the current temperature.
    gain : float
        Pass-band gain K.
    """

    name: str = "phase_shifter"
    rc_s: float = 1.0 / (2 * np.pi * 30740.0)
    gain: float = 1.0

    inputs = ("in",)
    outputs = ("out",)

    @classmethod
    def designed_for(cls, f_Hz: float, tc_rc_per_K: float = 0.0, delta_T_K: float = 0.0,
                     trim_rad: float = 0.0, gain: float = 1.0, name: str = "phase_shifter"):
        """A shifter giving 90 degrees (+ ``trim_rad``) at ``f_Hz`` at the design temperature.

        Parameters
        ----------
        f_Hz : float
            Design frequency.
        tc_rc_per_K : float, optional
            Temperature coefficient of RC (TCR + TCC), 1/K.
        delta_T_K : float, optional
            Temperature minus the design temperature.
        trim_rad : float, optional
            Extra lead at the design point (a deliberate phase error).
        gain : float, optional
            Pass-band gain.
        name : str, optional

        Returns
        -------
        AllPassPhaseShifter
        """
        # lead = pi - 2 atan(w RC) = pi/2 + trim  ->  w RC = tan(pi/4 - trim/2)
        rc0 = np.tan(np.pi / 4 - trim_rad / 2) / (2 * np.pi * f_Hz)
        return cls(name=name, rc_s=rc0 * (1 + tc_rc_per_K * delta_T_K), gain=gain)

    states = ("V",)

    def abcd(self) -> tuple:
        """``x' = (u - x)/RC``, ``y = K (u - 2x)``.

        Returns
        -------
        tuple
            ``(A, B, C, D)``.
        """
        a = 1.0 / self.rc_s
        return [[-a]], [[a]], [[-2 * self.gain]], [[self.gain]]

    def phase_lead_rad(self, f_Hz: float) -> float:
        """Phase lead ``pi - 2 atan(2 pi f RC)`` at ``f_Hz``.

        Parameters
        ----------
        f_Hz : float

        Returns
        -------
        float
        """
        return float(np.pi - 2 * np.arctan(2 * np.pi * f_Hz * self.rc_s))
