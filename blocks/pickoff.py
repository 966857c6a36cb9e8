"""Capacitive pickoff with a charge amplifier (drive-sense combs and sense electrodes)."""

from __future__ import annotations

from dataclasses import dataclass

from .base import LinearBlock, named_ss


@dataclass
class CapacitivePickoff(LinearBlock):
    """``v = sign * V_p * dC/dx / C_f * x + (C_ft / C_f) * v_ft``.

    A charge amplifier with feedback capacitor ``C_f`` reads the motional charge
    ``V_p dC/dx x``; stray capacitance ``C_ft`` from the drive electrodes adds the
    drive voltage (electrical feedthrough).

    Parameters
    ----------
    bias_V : float
        Proof-mass bias V_p.
    dC_dx_F_per_m : float
        Sensing capacitance gradient (2 C0/g for differential electrodes).
    c_feedback_F : float
        Charge-amplifier feedback capacitance C_f.
    c_feedthrough_F : float
        Stray capacitance from the drive voltage.
    sign : float
        Wiring polarity (+1 or -1).
    """

    name: str = "pickoff"
    bias_V: float = 5.0
    dC_dx_F_per_m: float = 3.5e-8
    c_feedback_F: float = 2e-12
    c_feedthrough_F: float = 0.0
    sign: float = 1.0

    inputs = ("x", "v_ft")
    outputs = ("out",)

    @property
    def gain_V_per_m(self) -> float:
        """Displacement gain ``sign V_p dC/dx / C_f``."""
        return self.sign * self.bias_V * self.dC_dx_F_per_m / self.c_feedback_F

    def linear_model(self):
        """A static gain from (x, v_ft) to the output voltage.

        Returns
        -------
        control.StateSpace
        """
        import numpy as np
        return named_ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((1, 0)),
                        [[self.gain_V_per_m, self.c_feedthrough_F / self.c_feedback_F]],
                        self.name, self.inputs, self.outputs, ())
