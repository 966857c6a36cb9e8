"""Named slices of flat vectors: the states, parameters and inputs of a compiled step function and its engine."""

from __future__ import annotations

import numpy as np


class Layout:
    """Ordered named fields of given shapes packed into one flat vector.

    Parameters
    ----------
    fields : list of (str, tuple)
        Field names with shapes (``()`` for a scalar, ``(n,)``, ``(n, m)``).
    """

    def __init__(self, fields):
        self.fields = list(fields)
        self.slices: dict[str, slice] = {}
        self.shapes: dict[str, tuple] = {}
        i = 0
        for name, shape in self.fields:
            size = int(np.prod(shape)) if shape else 1
            self.slices[name] = slice(i, i + size)
            self.shapes[name] = tuple(shape)
            i += size
        self.size = i

    def pack(self, values: dict) -> np.ndarray:
        """Flatten a dict of arrays into one vector (row-major for matrices).

        Parameters
        ----------
        values : dict
            One entry per field.

        Returns
        -------
        ndarray
        """
        out = np.zeros(self.size)
        for name, _ in self.fields:
            out[self.slices[name]] = np.ravel(np.asarray(values[name], dtype=float))
        return out

    def unpack(self, vec, name: str):
        """The field ``name`` of a flat (numeric or symbolic) vector.

        Matrices are returned as a list of rows for symbolic use (see :func:`matvec`).

        Parameters
        ----------
        vec : array-like
        name : str

        Returns
        -------
        object
        """
        sl = self.slices[name]
        shape = self.shapes[name]
        if not shape:
            return vec[sl.start]
        if len(shape) == 1:
            return [vec[sl.start + k] for k in range(shape[0])]
        n, m = shape
        return [[vec[sl.start + r * m + c] for c in range(m)] for r in range(n)]

    def get(self, vec: np.ndarray, name: str) -> np.ndarray:
        """Numeric field of a vector (or of each column of a matrix of vectors).

        Parameters
        ----------
        vec : ndarray, shape (size,) or (size, k)
        name : str

        Returns
        -------
        ndarray
        """
        return np.asarray(vec)[self.slices[name]]


def matvec(M, v):
    """Matrix (list of rows) times vector (list), written out element by element.

    Parameters
    ----------
    M : list of list
    v : list

    Returns
    -------
    list
    """
    return [sum((row[j] * v[j] for j in range(1, len(v))), row[0] * v[0]) for row in M]


def dot(a, b):
    """Inner product of two lists.

    Parameters
    ----------
    a, b : list

    Returns
    -------
    object
    """
    return sum((a[j] * b[j] for j in range(1, len(a))), a[0] * b[0])


def lpf_step(Phi, Gam, s, uin):
    """One exact step of a two-state filter ``s+ = Phi s + Gam uin`` (lists of rows), written out.

    Parameters
    ----------
    Phi : list of list
        2x2 transition matrix.
    Gam : list
        Input column (2 values).
    s : list
        The filter's two states.
    uin : object
        Its input, held over the step.

    Returns
    -------
    list
    """
    return [Phi[0][0] * s[0] + Phi[0][1] * s[1] + Gam[0] * uin,
            Phi[1][0] * s[0] + Phi[1][1] * s[1] + Gam[1] * uin]
