"""PI controller with output limits and anti-windup (block 7)."""

from __future__ import annotations

from dataclasses import dataclass

from .base import LinearBlock, named_ss
from .ops import numpy_ops


@dataclass
class PIController(LinearBlock):
    """``u = Kp e + Ki integral(e)``, clamped to ``[u_min_V, u_max_V]``.

    Anti-windup by conditional integration (clamping): the integrator holds while the
    output is saturated and the error would drive it further into saturation.

    Parameters
    ----------
    kp : float
        Proportional gain (V/V).
    ki_per_s : float
        Integral gain (1/s).
    u_min_V, u_max_V : float
        Output limits.
    """

    name: str = "pi"
    kp: float = 68.0
    ki_per_s: float = 330.0
    u_min_V: float = 0.0
    u_max_V: float = 10.0

    inputs = ("e",)
    outputs = ("u",)

    def linear_model(self):
        """Unsaturated face: ``x' = e``, ``u = Ki x + Kp e``.

        Returns
        -------
        control.StateSpace
        """
        return named_ss([[0.0]], [[1.0]], [[self.ki_per_s]], [[self.kp]], self.name,
                        self.inputs, self.outputs, ("integral",))

    def clamp_state(self, u_free, e):
        """Which limit clamps the output and whether the integrator holds (anti-windup by clamping).

        The output is clamped where the unclamped ``u_free = Kp e + Ki integral`` is beyond a
        limit; the integrator holds where it is clamped and the error ``e`` drives it further
        out. Written with comparisons and products only, so it serves numbers and symbols alike.

        Parameters
        ----------
        u_free : float or symbolic
            Unclamped output.
        e : float or symbolic
            Error input.

        Returns
        -------
        tuple
            ``(high, low, hold)``, each 0/1 (or a boolean): clamped at ``u_max_V``, clamped at
            ``u_min_V``, integrator held.
        """
        high = u_free > self.u_max_V
        low = u_free < self.u_min_V
        return high, low, high * (e > 0) + low * (e < 0)

    def carrier_step(self, integ, e, h_s, ops=numpy_ops):
        """One controller step of length ``h_s`` with error ``e`` (mean over the step).

        Parameters
        ----------
        integ : float or symbolic
            Integrator state (integral of e, V s).
        e : float or symbolic
            Error input.
        h_s : float
            Step length.
        ops : object, optional
            Math backend.

        Returns
        -------
        tuple
            (new integrator state, clamped output u).
        """
        u_free = self.kp * e + self.ki_per_s * (integ + e * h_s)
        _, _, hold = self.clamp_state(u_free, e)
        integ_new = ops.if_else(hold > 0, integ, integ + e * h_s)
        u = ops.fmin(ops.fmax(self.kp * e + self.ki_per_s * integ_new, self.u_min_V), self.u_max_V)
        return integ_new, u
