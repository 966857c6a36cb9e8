"""The PLL drive's envelope parameters as a smooth function of temperature (long runs over an oven).

The carrier engine builds one operating point per 1 mK, which a run over tens of kelvin cannot
afford at the envelope's speed. Here the packed parameters (and their rate and quadrature
directions) are built on a grid of die temperatures :data:`T_GRID_K` apart, at the run's board
offsets rounded to :data:`OFFSET_STEP_K`, and each output sample's row is their cubic (four-node
Lagrange) interpolation at the sample's die temperature: the matrix exponentials, lock frequency
and trims all move smoothly with temperature.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

#: Spacing of the die-temperature grid (K).
T_GRID_K = 2.5
#: Board-minus-die offsets are rounded to this step (K) (zero without a thermal lag).
OFFSET_STEP_K = 0.25
#: Grid nodes kept across runs in one process.
NODE_CACHE_SIZE = 256

_NODES: OrderedDict = OrderedDict()


def _lagrange_weights(t: np.ndarray) -> np.ndarray:
    """Weights of the nodes -1, 0, 1, 2 for the fractional positions ``t`` in [0, 1) (cubic Lagrange)."""
    return np.stack([-t * (t - 1) * (t - 2) / 6, (t + 1) * (t - 1) * (t - 2) / 2,
                     -(t + 1) * t * (t - 2) / 2, (t + 1) * t * (t - 1) / 6], axis=1)


class PLLEnvelopeTable:
    """Parameter rows of the PLL drive's envelope step for one unit, interpolated in die temperature.

    Parameters
    ----------
    make_node : callable
        ``(die_C, board_C) -> OperatingPlan`` at a grid node.
    key : tuple
        What the nodes depend on besides temperature (device content, step, noise switches, scale), for
        the cache shared across runs.
    """

    def __init__(self, make_node, key: tuple):
        self.make_node = make_node
        self.key = key

    def _node(self, i: int, off: float) -> tuple:
        ck = self.key + (i, off)
        node = _NODES.get(ck)
        if node is None:
            plan = self.make_node(i * T_GRID_K, i * T_GRID_K + off)
            packed = plan.layout.pack(plan.base)
            node = _NODES[ck] = (plan.layout, packed, plan.phi_rate.ravel(), plan.k_quad_N_per_m * plan.phi_quad.ravel(),
                                 plan.trim_rad)
            while len(_NODES) > NODE_CACHE_SIZE:
                _NODES.popitem(last=False)
        else:
            _NODES.move_to_end(ck)
        return node

    def rows(self, die_C, board_C, rate_rad_s, phase_offset_rad, vref_factor, quad_rel) -> np.ndarray:
        """Packed parameter rows, one per sample.

        Parameters
        ----------
        die_C, board_C : ndarray
            Die and board temperatures of the samples.
        rate_rad_s, phase_offset_rad, vref_factor, quad_rel : ndarray
            Per-sample rate, demodulation-phase offset, set-point factor, relative quadrature change.

        Returns
        -------
        ndarray, shape (k, n_p)
        """
        die_C = np.asarray(die_C, dtype=float)
        off = np.round((np.asarray(board_C, dtype=float) - die_C) / OFFSET_STEP_K) * OFFSET_STEP_K
        pos = die_C / T_GRID_K
        i0 = np.floor(pos).astype(int)
        W = _lagrange_weights(pos - i0)
        out = None
        for (i, o) in set(zip(i0.tolist(), off.tolist())):
            sel = np.flatnonzero((i0 == i) & (off == o))
            nodes = [self._node(i + d, o) for d in (-1, 0, 1, 2)]
            layout = nodes[0][0]
            if out is None:
                out = np.empty((die_C.size, layout.size))
            w = W[sel]
            P = sum(w[:, j:j + 1] * nodes[j][1][None, :] for j in range(4))
            phi = layout.slices["Phi"]
            P[:, phi] += sum(w[:, j:j + 1] * (rate_rad_s[sel, None] * nodes[j][2][None, :]
                                              + quad_rel[sel, None] * nodes[j][3][None, :]) for j in range(4))
            trim = sum(w[:, j] * nodes[j][4] for j in range(4)) + phase_offset_rad[sel]
            P[:, layout.slices["cos_ref"]] = np.cos(trim)[:, None]
            P[:, layout.slices["sin_ref"]] = np.sin(trim)[:, None]
            P[:, layout.slices["vref"]] *= vref_factor[sel, None]
            out[sel] = P
        return out


__all__ = ["PLLEnvelopeTable", "T_GRID_K", "OFFSET_STEP_K"]
