"""Block base classes: the contract every block follows."""

from __future__ import annotations

import functools
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

    #: State names of the linear face, for a block that gives its matrices through :meth:`abcd`.
    states: ClassVar[tuple] = ()

    def abcd(self) -> tuple:
        """The matrices ``A, B, C, D`` of the linear face (nested lists or arrays).

        A block defines either this (with :attr:`states`; :meth:`linear_model` then names the signals) or
        :meth:`linear_model` itself. Defining this lets :meth:`state_space_matrices` rebuild the matrices of
        a block whose parameters change between calls without building a named ``StateSpace``.

        Returns
        -------
        tuple
            ``(A, B, C, D)``.
        """
        raise NotImplementedError

    def linear_model(self) -> control.StateSpace:
        """The continuous-time state-space model with named inputs, outputs and states.

        Returns
        -------
        control.StateSpace
        """
        return named_ss(*self.abcd(), self.name, self.inputs, self.outputs, self.states)

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
            if type(self).abcd is not LinearBlock.abcd:  # the matrices without a named StateSpace
                mats = shaped_matrices(*self.abcd(), len(self.states), len(self.inputs), len(self.outputs))
            else:
                sys = self.linear_model()
                mats = (sys.A, sys.B, sys.C, sys.D)
            cached = (key, tuple(np.asarray(m, dtype=float) for m in mats))
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
        return C @ np.linalg.solve(1j * omega_rad_s * _eye(n) - A, B) + D


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
    A, B, C, D = shaped_matrices(A, B, C, D, len(states), len(inputs), len(outputs))
    return control.ss(A, B, C, D, name=name, inputs=list(inputs), outputs=list(outputs),
                      states=list(states) if states else None)


def shaped_matrices(A, B, C, D, n_states: int, n_inputs: int, n_outputs: int) -> tuple:
    """``A, B, C, D`` as float arrays of the shapes a system with these signal counts has.

    Parameters
    ----------
    A, B, C, D : array_like
        State-space matrices.
    n_states, n_inputs, n_outputs : int
        Signal counts.

    Returns
    -------
    tuple of ndarray
    """
    return (np.atleast_2d(np.asarray(A, dtype=float)).reshape(n_states, n_states),
            np.asarray(B, dtype=float).reshape(n_states, n_inputs),
            np.asarray(C, dtype=float).reshape(n_outputs, n_states),
            np.asarray(D, dtype=float).reshape(n_outputs, n_inputs))


@functools.lru_cache(maxsize=16)
def _eye(n: int) -> np.ndarray:
    """A read-only identity matrix of size ``n`` (the envelope face builds ``j w I - A`` many times)."""
    eye = np.eye(n)
    eye.flags.writeable = False
    return eye

