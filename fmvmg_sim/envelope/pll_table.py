"""The PLL drive's envelope parameters as a smooth function of temperature (long runs over an oven).

The carrier engine builds one operating point per 1 mK, which a run over tens of kelvin cannot
afford at the envelope's speed. Here the packed parameters (and their rate and quadrature
directions) are built on a grid of die temperatures :data:`T_GRID_K` apart and board-minus-die
offsets :data:`OFFSET_STEP_K` apart (a thermal lag puts the board off the die), and each output
sample's row is their cubic (four-node Lagrange) interpolation in the die temperature and linear
interpolation in the offset: the matrix exponentials, lock frequency and trims all move smoothly
with temperature.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

#: Spacing of the die-temperature grid (K).
T_GRID_K = 2.5
#: Spacing of the board-minus-die offset grid (K) (a single node at zero without a thermal lag).
OFFSET_STEP_K = 2.5
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
        opos = (np.asarray(board_C, dtype=float) - die_C) / OFFSET_STEP_K
        j0 = np.floor(opos).astype(int)
        wo = opos - j0
        pos = die_C / T_GRID_K
        i0 = np.floor(pos).astype(int)
        W = _lagrange_weights(pos - i0)
        out = None
        for (i, j) in set(zip(i0.tolist(), j0.tolist())):
            sel = np.flatnonzero((i0 == i) & (j0 == j))
            for jj, wj in ((j, 1.0 - wo[sel]), (j + 1, wo[sel])):
                if not np.any(wj):
                    continue
                nodes = [self._node(i + d, jj * OFFSET_STEP_K) for d in (-1, 0, 1, 2)]
                layout = nodes[0][0]
                if out is None:
                    out = np.zeros((die_C.size, layout.size))
                    trim_out = np.zeros(die_C.size)
                w = W[sel] * wj[:, None]
                P = sum(w[:, k:k + 1] * nodes[k][1][None, :] for k in range(4))
                P[:, layout.slices["Phi"]] += sum(w[:, k:k + 1] * (rate_rad_s[sel, None] * nodes[k][2][None, :]
                                                                   + quad_rel[sel, None] * nodes[k][3][None, :])
                                                  for k in range(4))
                out[sel] += P
                trim_out[sel] += sum(w[:, k] * nodes[k][4] for k in range(4))
        trim = trim_out + phase_offset_rad
        out[:, layout.slices["cos_ref"]] = np.cos(trim)[:, None]
        out[:, layout.slices["sin_ref"]] = np.sin(trim)[:, None]
        out[:, layout.slices["vref"]] *= vref_factor[:, None]
        return out


__all__ = ["PLLEnvelopeTable", "T_GRID_K", "OFFSET_STEP_K"]
