"""Quadrature demodulator of the drive pickoff against a PLL's oscillator (phase detector and amplitude)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Block


@dataclass
class QuadratureDetector(Block):
    """Two demodulators of ``v`` against the oscillator's outputs rotated by ``trim_rad``.

    With the oscillator at phase ``theta`` the references are ``cos(theta + trim)`` (the phase
    detector) and ``sin(theta + trim)`` (the in-phase, amplitude channel). A pickoff
    ``v = V sin(theta + trim + eps)`` gives ``pd = K_pd 2 mean(v cos(theta + trim)) = K_pd V sin(eps)``
    and ``amp = K_amp 2 mean(v sin(theta + trim)) = K_amp V cos(eps)``: the phase detector is zero
    when the pickoff is in phase with the rotated quadrature output, and the amplitude channel
    then reads the pickoff's amplitude.

    Parameters
    ----------
    trim_rad : float
        Reference rotation that cancels the pickoff chain's phase at the design point.
    k_pd : float
        Phase-detector scale (V per V of pickoff amplitude per rad).
    k_amp : float
        Amplitude-channel scale (V per V of pickoff amplitude).
    """

    name: str = "quadrature_detector"
    trim_rad: float = 0.0
    k_pd: float = 1.0
    k_amp: float = 1.0

    inputs = ("v", "cos_theta", "sin_theta")
    outputs = ("pd", "amp")

    def references(self, c, s):
        """The rotated references ``(cos(theta + trim), sin(theta + trim))`` from ``cos``, ``sin`` of theta.

        Parameters
        ----------
        c, s : float or symbolic
            Oscillator outputs.

        Returns
        -------
        tuple
        """
        ct, st = np.cos(self.trim_rad), np.sin(self.trim_rad)
        return c * ct - s * st, s * ct + c * st

    def carrier_mean(self, v0, v1, c0, s0, c1, s1):
        """Detector outputs from the step's end samples (trapezoid rule, exact for the DC part).

        Parameters
        ----------
        v0, v1 : float or symbolic
            Pickoff at the start and end of the step.
        c0, s0, c1, s1 : float or symbolic
            Oscillator outputs at the start and end of the step.

        Returns
        -------
        tuple
            ``(pd, amp)`` before any low-pass.
        """
        r0c, r0s = self.references(c0, s0)
        r1c, r1s = self.references(c1, s1)
        return (self.k_pd * (v0 * r0c + v1 * r1c), self.k_amp * (v0 * r0s + v1 * r1s))

    def baseband(self, V: complex) -> tuple:
        """Envelope face: outputs for the pickoff phasor ``V`` (``v = Re(V e^{j theta})``).

        Parameters
        ----------
        V : complex

        Returns
        -------
        tuple
            ``(pd, amp)``: ``K_pd Re(V e^{-j trim})`` and ``K_amp Re(j V e^{-j trim})``.
        """
        r = V * np.exp(-1j * self.trim_rad)
        return float(self.k_pd * r.real), float(-self.k_amp * r.imag)
