"""Block base classes: the contract every block follows."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

import control
import numpy as np


@dataclass
class Block:
    """A block of the diagram: a bag of physical parameters with named signals.

    Subclasses are dataclasses whose fields are parameters in SI units (names carry
    the unit). ``inputs`` and ``outputs`` name the signals for wiring.
    """

    name: str = "block"

    #: Signal names (overridden by subclasses).
    inputs: ClassVar[tuple] = ()
    outputs: ClassVar[tuple] = ()

    def params(self) -> dict:
        """Parameters as a plain dict (for reports and hashing).

        Returns
        -------
        dict
            Field name to value.
        """
        return {f.name: getattr(self, f.name) for f in fields(self)}


#: Field names of each block class (the parameters :meth:`LinearBlock.state_space_matrices` keys its cache on).
_FIELD_NAMES: dict = {}


@dataclass
class LinearBlock(Block):
    """A block with a linear face: ``linear_model()`` gives its python-control model.

    Affine terms (offsets) are not part of a ``StateSpace``; a block with an offset
    returns it from :meth:`output_offset`, added to its outputs by the engines.
    """

    def linear_model(self) -> control.StateSpace:
        """The continuous-time state-space model with named inputs, outputs and states.

        Returns
        -------
        control.StateSpace
        """
        raise NotImplementedError

    def output_offset(self) -> np.ndarray:
        """Constant added to each output (V or the output's unit); zeros by default.

        Returns
        -------
        ndarray
            One value per output.
        """
        return np.zeros(len(self.outputs))

    def state_scale(self) -> np.ndarray:
        """Typical magnitude of each state, used by engines to balance their matrices.

        Returns
        -------
        ndarray
            One positive value per state (ones by default).
        """
        return np.ones(self.linear_model().nstates)

    def state_space_matrices(self) -> tuple:
        """``A, B, C, D`` of :meth:`linear_model` as float arrays, rebuilt only when a parameter changes.

        The envelope face evaluates a block at many frequencies with the same parameters (a root
        search for the loop's oscillation frequency calls it dozens of times per steady state), and
        building a named ``StateSpace`` costs far more than the evaluation. The matrices are kept
        with the parameter values they were built from and reused while those values compare equal
        (parameters are numbers, strings or tuples of them, changed by assignment); callers must not
        modify the arrays.

        Returns
        -------
        tuple of ndarray
            ``(A, B, C, D)``.
        """
        names = _FIELD_NAMES.get(type(self))
        if names is None:
            names = _FIELD_NAMES[type(self)] = tuple(f.name for f in fields(self))
        key = tuple(map(self.__dict__.get, names))
        cached = self.__dict__.get("_state_space_cache")
        if cached is None or cached[0] != key:
            sys = self.linear_model()
            cached = (key, tuple(np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D)))
            self.__dict__["_state_space_cache"] = cached
        return cached[1]

    def frequency_response(self, omega_rad_s: float) -> np.ndarray:
        """Complex gain matrix ``C (j w I - A)^-1 B + D`` at ``omega_rad_s`` (envelope face).

        Parameters
        ----------
        omega_rad_s : float
            Angular frequency in rad/s.

        Returns
        -------
        ndarray
            Complex array of shape (n_outputs, n_inputs).
        """
        A, B, C, D = self.state_space_matrices()
        n = A.shape[0]
        if n == 0:
            return D.astype(complex)
        return C @ np.linalg.solve(1j * omega_rad_s * np.eye(n) - A, B) + D


def named_ss(A, B, C, D, name: str, inputs, outputs, states) -> control.StateSpace:
    """Build a python-control ``StateSpace`` with signal names.

    Parameters
    ----------
    A, B, C, D : array_like
        State-space matrices.
    name : str
        System name.
    inputs, outputs, states : sequence of str
        Signal names.

    Returns
    -------
    control.StateSpace
    """
    A = np.atleast_2d(np.asarray(A, dtype=float)).reshape(len(states), len(states))
    B = np.asarray(B, dtype=float).reshape(len(states), len(inputs))
    C = np.asarray(C, dtype=float).reshape(len(outputs), len(states))
    D = np.asarray(D, dtype=float).reshape(len(outputs), len(inputs))
    return control.ss(A, B, C, D, name=name, inputs=list(inputs), outputs=list(outputs),
                      states=list(states) if states else None)
