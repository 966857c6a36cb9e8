"""Closed-loop sense blocks: the force-to-rebalance controller and the quadrature-tuning electrodes.

The force-to-rebalance loop of a mode-split gyroscope acts on the demodulated sense signal: a
fourth-order low-pass removes the demodulator's 2-omega ripple, a PID drives the feedback voltage,
which the drive reference remodulates onto the force-rebalance combs (an :class:`ElectrostaticDrive`
and a :class:`Multiplier` of the library). The quadrature loop acts on the quadrature-demodulated
signal through the same controller (with no derivative) and sets a DC voltage on the
quadrature-tuning electrodes, an electrostatic coupling stiffness between the modes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import LinearBlock


@dataclass
class RebalanceController(LinearBlock):
    """Demodulation low-pass and PID: ``u = (Kp + Ki/s + Kd s) F(s) e``, ``F`` two cascaded 2nd-order sections.

    Why a PID and not a PI: in a mode-split gyroscope the demodulated sense mode is a second-order
    resonance at the mode split with the sense mode's own damping (a Q of 1e4 at 30 kHz leaves a
    decay rate of about 10 1/s). A PI on it can only stiffen that resonance (its proportional
    part acts as an electrostatic spring), so a stable PI loop is slower than the sense mode's
    own bandwidth, about 1 Hz. The derivative of the demodulated signal is a feedback force in
    phase with the sense velocity in the rotating frame: it damps the ringing at the split, and
    the loop bandwidth can reach tens of Hz. The derivative is taken from the last section's own
    second state, so the controller stays strictly proper.

    Why a fourth-order filter: the demodulator leaves a 2-omega ripple (and folds the front end's noise
    from 3 omega there); what of it reaches the derivative is remodulated into a force at omega. Through
    one 2nd-order section at 2 kHz the derivative passes the 2-omega band with a gain
    ``Kd w_c^2 / (2 w)``, about 6 at the shipped gains; through two, about 0.01, for about 6 degrees of
    phase at the mode split.

    Parameters
    ----------
    f_c_Hz : float
        Corner of each low-pass section (Hz).
    q : float
        Pole quality factor of each section (Butterworth for 1/sqrt(2)).
    kp : float
        Proportional gain (V/V).
    ki_per_s : float
        Integral gain (1/s).
    kd_s : float
        Derivative gain (s).
    """

    name: str = "rebalance_controller"
    f_c_Hz: float = 2000.0
    q: float = 1 / np.sqrt(2)
    kp: float = 0.0
    ki_per_s: float = 100.0
    kd_s: float = 0.0

    inputs = ("e",)
    outputs = ("u",)
    states = ("y1", "dy1", "y", "dy", "integral")

    @property
    def omega_c_rad_s(self) -> float:
        """Corner of each low-pass section in rad/s."""
        return 2 * np.pi * self.f_c_Hz

    def abcd(self) -> tuple:
        """States ``(y1, y1'/w_c, y, y'/w_c, integral of y)``; ``u = Kp y + Kd w_c (y'/w_c) + Ki integral``.

        Returns
        -------
        tuple
            ``(A, B, C, D)``.
        """
        wc = self.omega_c_rad_s
        q = self.q
        A = [[0.0, wc, 0.0, 0.0, 0.0], [-wc, -wc / q, 0.0, 0.0, 0.0],
             [0.0, 0.0, 0.0, wc, 0.0], [wc, 0.0, -wc, -wc / q, 0.0],
             [0.0, 0.0, 1.0, 0.0, 0.0]]
        B = [[0.0], [wc], [0.0], [0.0], [0.0]]
        C = [[0.0, 0.0, self.kp, self.kd_s * wc, self.ki_per_s]]
        return A, B, C, [[0.0]]

    def state_for_output(self, u_V: float) -> np.ndarray:
        """The controller's state that holds the output ``u_V`` with zero error (the integrator carries it).

        Parameters
        ----------
        u_V : float

        Returns
        -------
        ndarray
            One value per state.
        """
        return np.array([0.0, 0.0, 0.0, 0.0, u_V / self.ki_per_s if self.ki_per_s > 0 else 0.0])


@dataclass
class QuadratureTuningElectrodes(LinearBlock):
    """Differential quadrature-tuning electrodes: a coupling stiffness linear in the tuning voltage.

    With the proof mass at ``V_p`` and ``V_p +- V_t`` on the two electrode halves, the coupling
    stiffness is ``k_t (V_p + V_t)^2 - k_t (V_p - V_t)^2 = 4 k_t V_p V_t``: linear in ``V_t``.
    ``dk_dV`` is that slope.

    Parameters
    ----------
    dk_dV_N_per_m_per_V : float
        Coupling stiffness per volt of tuning voltage (N/m/V).
    """

    name: str = "quadrature_electrodes"
    dk_dV_N_per_m_per_V: float = 1.0

    inputs = ("v_t",)
    outputs = ("dk_quad",)
    states = ()

    def abcd(self) -> tuple:
        """A static gain.

        Returns
        -------
        tuple
            ``(A, B, C, D)``.
        """
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[self.dk_dV_N_per_m_per_V]]
