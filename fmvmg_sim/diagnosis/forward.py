"""The quasi-static forward model: every channel of a long record from steady states on a grid.

Thermal effects are slow against the loop dynamics (the drive loop settles in tens of ms, the
output filter in ms), so at each instant the gyro sits on the averaged model's periodic steady
state (:func:`fmvmg_sim.averaged.steady_state`) at its die temperature. The model computes that
steady state on a temperature grid (base response, plus the linear sensitivity to an applied rate
and to a relative change of the quadrature stiffness), interpolates it with cubic splines and
adds the time-history signals of the effects (:meth:`fmvmg_sim.effects.EffectSet.signals`).

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
    """

    grid_C: np.ndarray
    base: np.ndarray
    d_rate: np.ndarray
    d_quad: np.ndarray
    _splines: dict = field(default_factory=dict, repr=False)

    def spline(self, which: str) -> CubicSpline:
        """Cubic spline (over temperature) of ``base``, ``d_rate`` or ``d_quad``.

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
                 quad_rel: np.ndarray | None = None) -> np.ndarray:
        """Channels at die temperatures, with an equivalent rate and a quadrature change.

        Parameters
        ----------
        die_C : ndarray, shape (n,)
        rate_dps : ndarray, optional
            Applied plus equivalent rate (deg/s).
        quad_rel : ndarray, optional
            Relative quadrature-stiffness change.

        Returns
        -------
        ndarray, shape (n, C)
        """
        y = self.spline("base")(die_C)
        if rate_dps is not None and np.any(rate_dps != 0):
            y = y + self.spline("d_rate")(die_C) * np.asarray(rate_dps)[:, None]
        if quad_rel is not None and np.any(quad_rel != 0):
            y = y + self.spline("d_quad")(die_C) * np.asarray(quad_rel)[:, None]
        return y

    def slope(self, die_C: np.ndarray) -> np.ndarray:
        """Temperature derivative of the base response (per K).

        Parameters
        ----------
        die_C : ndarray

        Returns
        -------
        ndarray, shape (n, C)
        """
        return self.spline("base")(die_C, 1)


def response_table(device, grid_C: np.ndarray, with_rate: bool = True, with_quad: bool = True) -> ResponseTable:
    """Steady states of ``device`` on ``grid_C`` (3 per point: base, rate step, quadrature step).

    Parameters
    ----------
    device : fmvmg_sim.device.Device
        With any temperature-law effects already folded in.
    grid_C : ndarray
    with_rate, with_quad : bool, optional
        Skip a sensitivity (left zero) to save time.

    Returns
    -------
    ResponseTable
    """
    G, C = len(grid_C), len(CHANNELS)
    base, dr, dq = np.zeros((G, C)), np.zeros((G, C)), np.zeros((G, C))
    for i, T in enumerate(grid_C):
        dg = build_diagram(device, float(T))
        b = np.array(_row(steady_state(dg), dg))
        base[i] = b
        if with_rate:
            dr[i] = (np.array(_row(steady_state(dg, np.deg2rad(_RATE_STEP_DPS)), dg)) - b) / _RATE_STEP_DPS
        if with_quad:
            dq_g = build_diagram(device, float(T), quad_delta_rel=_QUAD_STEP)
            dq[i] = (np.array(_row(steady_state(dq_g), dq_g)) - b) / _QUAD_STEP
    return ResponseTable(np.asarray(grid_C, dtype=float), base, dr, dq)


def die_and_signals(effects: dict, t_s: np.ndarray, case_C: np.ndarray) -> tuple[np.ndarray, dict]:
    """Die temperature and time-history signals of the effects on a record's time base.

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
    return table.evaluate(die, rate, sig["quad_rel"])


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
    tab = response_table(dev, grid, with_rate=has_rate, with_quad=has_quad)
    y = predict(tab, effects, t_s, case_C, rate_true_dps)
    out = {c: y[:, i] for i, c in enumerate(CHANNELS)}
    out["die_temperature_C"] = die
    return out
