"""Electrostatic comb drive with DC superposition (blocks 9-10 and the drive combs).

For comb gradients ``C'(1 +- eps)`` on the two sides and voltages ``V_1,2 = VDC +- v``
(push-pull) the force is ``F = 2 C' VDC v + eps C' (VDC^2 + v^2)``; single-sided
(``V = VDC + v`` on one comb) gives ``F = C' VDC v + C'/2 (VDC^2 + v^2)``. With
``v = U sin(theta)`` the ``v^2`` term holds a DC force and the 2-omega term
``-(coef) U^2/2 cos(2 theta)`` (physics brief section 1).
"""

from __future__ import annotations

from dataclasses import dataclass

from .base import LinearBlock, named_ss


@dataclass
class ElectrostaticDrive(LinearBlock):
    """Force on the drive mode from the AC drive voltage superposed on VDC.

    Parameters
    ----------
    dC_dx_F_per_m : float
        Comb capacitance gradient per side, C'.
    vdc_V : float
        DC bias VDC (block 9).
    topology : {"push-pull", "single-sided"}
        Comb arrangement.
    asymmetry : float
        Gradient mismatch eps between the two sides (push-pull only).
    """

    name: str = "comb_drive"
    dC_dx_F_per_m: float = 7.1e-8
    vdc_V: float = 10.0
    topology: str = "push-pull"
    asymmetry: float = 0.0

    inputs = ("v_ac",)
    outputs = ("F_x",)

    @property
    def linear_coef_N_per_V(self) -> float:
        """dF/dv at v = 0: ``2 C' VDC`` (push-pull) or ``C' VDC`` (single-sided)."""
        return (2.0 if self.topology == "push-pull" else 1.0) * self.dC_dx_F_per_m * self.vdc_V

    @property
    def quadratic_coef_N_per_V2(self) -> float:
        """Coefficient of ``(VDC^2 + v^2)``: ``eps C'`` or ``C'/2``."""
        if self.topology == "push-pull":
            return self.asymmetry * self.dC_dx_F_per_m
        return 0.5 * self.dC_dx_F_per_m

    def linear_model(self):
        """The linear part ``F = coef * v``.

        Returns
        -------
        control.StateSpace
        """
        import numpy as np
        return named_ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)),
                        [[self.linear_coef_N_per_V]], self.name, self.inputs, self.outputs, ())

    def quadratic_force(self, v_ac):
        """The nonlinear part ``coef2 (VDC^2 + v^2)`` (DC force and the 2-omega term), in N.

        Parameters
        ----------
        v_ac : float or symbolic
            AC drive voltage.

        Returns
        -------
        float or symbolic
        """
        return self.quadratic_coef_N_per_V2 * (self.vdc_V ** 2 + v_ac * v_ac)
