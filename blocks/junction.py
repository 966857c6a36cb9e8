"""Summing junction / comparator (block 5: ``e = Vref - r``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import LinearBlock, named_ss


@dataclass
class SummingJunction(LinearBlock):
    """``y = sum_i s_i u_i`` with signs ``s_i`` (a comparator is signs (+1, -1)).

    Parameters
    ----------
    signs : tuple of float
        One sign (or weight) per input.
    """

    name: str = "sum"
    signs: tuple = (1.0, -1.0)

    @property
    def inputs(self):  # type: ignore[override]
        return tuple(f"in{i}" for i in range(len(self.signs)))

    outputs = ("out",)

    def linear_model(self):
        """A static gain row.

        Returns
        -------
        control.StateSpace
        """
        return named_ss(np.zeros((0, 0)), np.zeros((0, len(self.signs))), np.zeros((1, 0)),
                        [list(self.signs)], self.name, self.inputs, self.outputs, ())
