"""The quasi-static forward model: every channel of a long record from steady states on a grid.

Thermal effects are slow against the loop dynamics (the drive loop settles in tens of ms, the
output filter in ms), so at each instant the gyro sits on the averaged model's periodic steady
state (:func:`fmvmg_sim.averaged.steady_state`) at its die temperature (the MEMS laws) and its board
temperature (the electronics, which stay on the case under a thermal lag). The model computes that
steady state on a temperature grid with the board at the die (base response, plus the linear
sensitivities to an applied rate, to a relative change of the quadrature stiffness and to the board
standing off the die), interpolates it with cubic splines and adds the time-history signals of the
effects (:meth:`fmvmg_sim.effects.EffectSet.signals`).

A 13 h record at 10 Hz is predicted in a few ms once the ~60 steady states (0.2 s) are known;
:func:`fmvmg_sim.envelope.engine.run_envelope` (with noise) stays the reference and builds the null.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from ..averaged import steady_state
from ..diagram import build_diagram
from ..effects import EffectSet

#: Channels the forward model predicts (record names; rate in V, the raw output).
CHANNELS = ("rate_V", "quadrature_V", "drive_amplitude_V", "agc_effort_V", "drive_frequency_Hz")
IRATE, IQUAD, IAMP, IAGC, IFREQ = range(len(CHANNELS))
#: Grid spacing (K): cubic interpolation error below 1e-4 of the thermal swing at 5 K (tested).
GRID_K = 5.0
_RATE_STEP_DPS = 1.0
_QUAD_STEP = 1e-3
#: Board-temperature step (K) of the board sensitivities (central differences, first and second order).
_BOARD_STEP_K = 2.0


def temperature_grid(t_min_C: float, t_max_C: float, spacing_K: float = GRID_K) -> np.ndarray:
    """Grid covering ``[t_min_C, t_max_C]`` with one spacing of margin on each side (>= 4 points).

    Parameters
    ----------
    t_min_C, t_max_C : float
    spacing_K : float, optional

    Returns
    -------
    ndarray
    """
    lo, hi = float(t_min_C) - spacing_K, float(t_max_C) + spacing_K
    n = max(4, int(np.ceil((hi - lo) / spacing_K)) + 1)
    return np.linspace(lo, hi, n)


def _row(ss, dg) -> list:
    return [ss.rate_V, ss.quadrature_V, dg.vref_V, ss.agc_effort_V, ss.f_Hz]


@dataclass
class ResponseTable:
    """Quasi-static responses on a temperature grid.

    Attributes
    ----------
    grid_C : ndarray, shape (G,)
    base : ndarray, shape (G, C)
        Channels at zero rate and nominal quadrature (C = len(CHANNELS)).
    d_rate : ndarray, shape (G, C)
        Change per deg/s of applied (or equivalent) rate.
    d_quad : ndarray, shape (G, C)
        Change per unit relative quadrature-stiffness change.
    d_board : ndarray, shape (G, C), optional
        Change per kelvin of the board (the electronics) above the die; None when not computed.
    d2_board : ndarray, shape (G, C), optional
        Second derivative in the board temperature (per K^2; the electronic phase enters the output through a
        cosine and the bandwidth through a reciprocal, so tens of kelvin of board offset need it).
    d_rate_board, d_quad_board : ndarray, shape (G, C), optional
        Change of ``d_rate`` and ``d_quad`` per kelvin of board offset (the electronic phase turns a rate or a
        quadrature change between the two demodulated channels).
    """

    grid_C: np.ndarray
    base: np.ndarray
    d_rate: np.ndarray
    d_quad: np.ndarray
    d_board: np.ndarray | None = None
    d2_board: np.ndarray | None = None
    d_rate_board: np.ndarray | None = None
    d_quad_board: np.ndarray | None = None
    _splines: dict = field(default_factory=dict, repr=False)

    def spline(self, which: str) -> CubicSpline:
        """Cubic spline (over temperature) of ``base``, ``d_rate``, ``d_quad``, ``d_board`` or ``d2_board``.

        Parameters
        ----------
        which : str

        Returns
        -------
        CubicSpline
        """
        if which not in self._splines:
            self._splines[which] = CubicSpline(self.grid_C, getattr(self, which), axis=0)
        return self._splines[which]

    def evaluate(self, die_C: np.ndarray, rate_dps: np.ndarray | None = None,
                 quad_rel: np.ndarray | None = None, board_offset_K: np.ndarray | None = None) -> np.ndarray:
        """Channels at die temperatures, with an equivalent rate, a quadrature change and the board off the die.

        Parameters
        ----------
        die_C : ndarray, shape (n,)
        rate_dps : ndarray, optional
            Applied plus equivalent rate (deg/s).
        quad_rel : ndarray, optional
            Relative quadrature-stiffness change.
        board_offset_K : ndarray, optional
            Board minus die temperature (K); needs a table built with the board sensitivity.

        Returns
        -------
        ndarray, shape (n, C)
        """
        y = self.spline("base")(die_C)
        board = board_offset_K is not None and np.any(board_offset_K != 0)
        if board and self.d_board is None:
            raise ValueError("this response table was built without the board sensitivity")
        o = np.asarray(board_offset_K)[:, None] if board else 0.0
        for name, u in (("rate", rate_dps), ("quad", quad_rel)):
            if u is not None and np.any(u != 0):
                d = self.spline(f"d_{name}")(die_C)
                if board and getattr(self, f"d_{name}_board") is not None:
                    d = d + self.spline(f"d_{name}_board")(die_C) * o
                y = y + d * np.asarray(u)[:, None]
        if board:
            y = y + (self.spline("d_board")(die_C) + 0.5 * self.spline("d2_board")(die_C) * o) * o
        return y

    def slope(self, die_C: np.ndarray) -> np.ndarray:
        """Temperature derivative of the base response (per K), die and board moving together.

        Parameters
        ----------
        die_C : ndarray

        Returns
        -------
        ndarray, shape (n, C)
        """
        return self.spline("base")(die_C, 1)

    def die_slope(self, die_C: np.ndarray) -> np.ndarray:
        """Derivative of the base response in the die temperature alone, the board held (per K).

        Parameters
        ----------
        die_C : ndarray

        Returns
        -------
        ndarray, shape (n, C)
        """
        d = self.slope(die_C)
        return d if self.d_board is None else d - self.spline("d_board")(die_C)


def response_table(device, grid_C: np.ndarray, with_rate: bool = True, with_quad: bool = True,
                   with_board: bool = False) -> ResponseTable:
    """Steady states of ``device`` on ``grid_C`` (base, rate step, quadrature step, board steps).

    Parameters
    ----------
    device : fmvmg_sim.device.Device
        With any temperature-law effects already folded in.
    grid_C : ndarray
    with_rate, with_quad : bool, optional
        Skip a sensitivity (left zero) to save time.
    with_board : bool, optional
        Also the sensitivity to the board standing off the die (two more steady states per point), which a
        thermal lag needs.

    Returns
    -------
    ResponseTable
    """
    G, C = len(grid_C), len(CHANNELS)
    base, dr, dq = np.zeros((G, C)), np.zeros((G, C)), np.zeros((G, C))
    db, db2, drb, dqb = (np.zeros((G, C)) for _ in range(4)) if with_board else (None,) * 4
    for i, T in enumerate(grid_C):
        dg = build_diagram(device, float(T))
        b = np.array(_row(steady_state(dg), dg))
        base[i] = b
        if with_rate:
            dr[i] = (np.array(_row(steady_state(dg, np.deg2rad(_RATE_STEP_DPS)), dg)) - b) / _RATE_STEP_DPS
        if with_quad:
            dq_g = build_diagram(device, float(T), quad_delta_rel=_QUAD_STEP)
            dq[i] = (np.array(_row(steady_state(dq_g), dq_g)) - b) / _QUAD_STEP
        if with_board:
            y, d_r, d_q = {}, {}, {}
            for sgn in (1.0, -1.0):
                Tb = float(T) + sgn * _BOARD_STEP_K
                g = build_diagram(device, float(T), board_C=Tb)
                y[sgn] = np.array(_row(steady_state(g), g))
                if with_rate:
                    d_r[sgn] = (np.array(_row(steady_state(g, np.deg2rad(_RATE_STEP_DPS)), g)) - y[sgn]) / _RATE_STEP_DPS
                if with_quad:
                    gq = build_diagram(device, float(T), board_C=Tb, quad_delta_rel=_QUAD_STEP)
                    d_q[sgn] = (np.array(_row(steady_state(gq), gq)) - y[sgn]) / _QUAD_STEP
            db[i] = (y[1.0] - y[-1.0]) / (2 * _BOARD_STEP_K)
            db2[i] = (y[1.0] - 2 * b + y[-1.0]) / _BOARD_STEP_K ** 2
            if with_rate:
                drb[i] = (d_r[1.0] - d_r[-1.0]) / (2 * _BOARD_STEP_K)
            if with_quad:
                dqb[i] = (d_q[1.0] - d_q[-1.0]) / (2 * _BOARD_STEP_K)
    return ResponseTable(np.asarray(grid_C, dtype=float), base, dr, dq, db, db2, drb, dqb)


def die_and_signals(effects: dict, t_s: np.ndarray, case_C: np.ndarray) -> tuple[np.ndarray, dict]:
    """Die temperature and time-history signals of the effects on a record's time base (the board is the case).

    Parameters
    ----------
    effects : dict
        ``{effect: {param: value}}``.
    t_s : ndarray
        Times from the start of the run (s).
    case_C : ndarray
        Sensor (case) temperature, gap-free and smooth.

    Returns
    -------
    die_C : ndarray
    signals : dict
        ``rate_dps`` and ``quad_rel``.
    """
    fx = EffectSet(effects)
    die = fx.die_temperature(t_s, case_C)
    return die, fx.signals(t_s, die)


def predict(table: ResponseTable, effects: dict, t_s: np.ndarray, case_C: np.ndarray,
            rate_true_dps: np.ndarray | None = None) -> np.ndarray:
    """All channels of a run: the table (device with effects folded in) on the effects' die path.

    Parameters
    ----------
    table : ResponseTable
        Built from the device with the temperature-law effects of ``effects`` folded in.
    effects : dict
        The effects (their die-temperature and time-history parts are applied here).
    t_s, case_C : ndarray
    rate_true_dps : ndarray, optional

    Returns
    -------
    ndarray, shape (n, C)
    """
    die, sig = die_and_signals(effects, t_s, case_C)
    rate = sig["rate_dps"] + (0.0 if rate_true_dps is None else np.asarray(rate_true_dps))
    board = np.asarray(case_C, dtype=float) - die if "thermal_lag" in effects else None
    return table.evaluate(die, rate, sig["quad_rel"], board)


def predict_device(device, effects: dict, t_s: np.ndarray, case_C: np.ndarray,
                   rate_true_dps: np.ndarray | None = None, spacing_K: float = GRID_K) -> dict:
    """Convenience: build the table for ``device`` (effects folded in) and predict a run.

    Parameters
    ----------
    device : fmvmg_sim.device.Device
        Without the effects (they are folded in here).
    effects : dict
    t_s, case_C : ndarray
    rate_true_dps : ndarray, optional
    spacing_K : float, optional

    Returns
    -------
    dict
        ``{channel: ndarray}`` plus ``die_temperature_C``.
    """
    dev = EffectSet(effects).apply_to_device(device) if effects else device
    die, _ = die_and_signals(effects, t_s, case_C)
    grid = temperature_grid(np.min(die), np.max(die), spacing_K)
    has_rate = rate_true_dps is not None and np.any(rate_true_dps != 0) or "temperature_rate" in effects
    has_quad = "thermal_hysteresis" in effects or "stress_relaxation" in effects
    tab = response_table(dev, grid, with_rate=has_rate, with_quad=has_quad, with_board="thermal_lag" in effects)
    y = predict(tab, effects, t_s, case_C, rate_true_dps)
    out = {c: y[:, i] for i, c in enumerate(CHANNELS)}
    out["die_temperature_C"] = die
    return out
