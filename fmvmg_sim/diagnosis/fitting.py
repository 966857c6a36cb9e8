"""Linearised weighted least squares on block data: the engine under calibration and attribution.

A model is the quasi-static forward model of a device (nominal deviations ``theta`` and
temperature-law effects folded in) on a path (die temperature, equivalent rate, quadrature
change: the path effects). Around a linearisation point its block predictions are
``y0 + sum_k cols_k (x_k - x0_k)``; the columns are finite-difference response tables
(device parameters) or analytic (path-effect amplitudes). Gauss-Newton rebuilds ``y0`` (and the
effect columns) at the new point; the nominal columns are built once, at calibration.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear

from ..effects import MODELS, EffectSet
from .converter import Converter, misread_nll, staircase_moments
from .data import FLOORS, Prepared
from .forward import CHANNELS, ResponseTable, response_table, temperature_grid
from ..uncertainty import law_curvature
from .parameters import KnobSet, apply_effects, apply_nominal

#: Effects folded into the device (temperature laws); the others act on the path or the noise.
DEVICE_EFFECTS = ("demod_phase_drift", "quadrature_drift", "q_factor_drift", "mode_split_drift",
                  "feedthrough", "duffing", "reference_drift")
PATH_EFFECTS = ("thermal_lag", "thermal_hysteresis", "temperature_rate", "stress_relaxation")
NOISE_EFFECTS = ("flicker_noise", "quantization")


@dataclass
class Lin:
    """A linearised model on blocks.

    Attributes
    ----------
    y0 : ndarray, shape (n, C)
        Prediction at ``x0``.
    cols : ndarray, shape (n, C, K)
        Sensitivities.
    names : list of str
    x0 : ndarray, shape (K,)
    prior_sd : ndarray, shape (K,)
        Prior standard deviation about 0 (NaN: no prior).
    lo, hi : ndarray
        Bounds.
    """

    y0: np.ndarray
    cols: np.ndarray
    names: list
    x0: np.ndarray
    prior_sd: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Block predictions at ``x``.

        Parameters
        ----------
        x : ndarray

        Returns
        -------
        ndarray, shape (n, C)
        """
        return self.y0 + self.cols @ (np.asarray(x) - self.x0)

    def predict_sd(self, cov: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Standard deviation of the block predictions on ``rows`` under a parameter covariance ``cov``.

        Parameters
        ----------
        cov : ndarray, shape (K, K)
        rows : ndarray of bool

        Returns
        -------
        ndarray, shape (m, C)
            ``sqrt(diag(J cov J^T))``; zero where a sensitivity is not finite (an absent channel).
        """
        J = np.nan_to_num(self.cols[rows])
        var = np.einsum("nck,kl,ncl->nc", J, np.nan_to_num(cov), J, optimize=True)
        return np.sqrt(np.clip(var, 0.0, None))


@dataclass
class Solution:
    """A weighted least-squares solution.

    Attributes
    ----------
    x : ndarray
    cov : ndarray
        Covariance with each channel's rows scaled by that channel's own reduced chi-square (when above 1).
    cost : float
        Weighted sum of squares of the data rows.
    n : int
        Data rows used.
    cov_noise : ndarray, optional
        Covariance under the noise model alone (not inflated by a systematic misfit), with the parameters at
        an active bound held fixed (zero rows and columns): a bound that holds a knob removes that knob's
        collinearity with the others, which a covariance with every parameter free would still charge them.
    """

    x: np.ndarray
    cov: np.ndarray
    cost: float
    n: int
    cov_noise: np.ndarray | None = None

    def param_cov(self) -> np.ndarray:
        """The covariance under the noise model (:attr:`cov_noise`) when known, else :attr:`cov`.

        Returns
        -------
        ndarray
        """
        return self.cov if self.cov_noise is None else self.cov_noise


class Fitter:
    """Block data of one record plus the forward model of one device.

    Parameters
    ----------
    prep : Prepared
    device : fmvmg_sim.device.Device
        The data-sheet (nominal) device.
    tables : dict, optional
        A store of response tables shared with other Fitters. A table depends only on the device, the
        temperature grid and its inputs, so Fitters on records of one profile (several simulations of the same
        oven and rate table) reuse each other's tables; the store keeps each device it holds tables of.
    quadrature_polarity : float, optional
        +1 or -1: the sign the record's quadrature output carries against the device's (which way the quadrature
        reference is wired; the demodulated outputs turn the other way with the phase error under the other sign).
    """

    def __init__(self, prep: Prepared, device, tables: dict | None = None, quadrature_polarity: float = 1.0):
        self.prep = prep
        self.device0 = device
        #: Sign of the recorded quadrature output against the device's (the quadrature reference's wiring)
        self.quadrature_polarity = float(quadrature_polarity)
        self.Y = prep.block_obs()
        self.S = prep.block_sigma()
        #: Blocks where the applied rate changes (and the next): the quasi-static model does not
        #: describe the sense chain's transient, so the rate channel is left out there
        self.transient_b = transient_blocks(prep)
        self.Y[self.transient_b, CHANNELS.index("rate_V")] = np.nan
        self.present = np.array([c in prep.channels for c in CHANNELS])
        self.has_rate = bool(np.any(prep.rate_true_dps != 0))
        c = prep.case_C
        self.grid = temperature_grid(np.min(c) - 6.0, np.max(c) + 6.0)
        self.rate_b = prep.block_mean(prep.rate_true_dps)
        #: The nominal knobs (the device's stated uncertainty)
        self.knobs = KnobSet.of(device)
        self._chan = [(k, CHANNELS.index(k.channel)) for k in self.knobs.knobs
                      if not k.on_device and k.channel in CHANNELS]
        #: How much later than the channels the temperature is read (s): the model's input is the reading
        #: this much later (the calibrated ``temperature_delay_s``)
        self.delay_s = 0.0
        #: Each block's recorded temperature from the device's reference (the channels' gain coefficients)
        self._dT_b = np.nan_to_num(prep.block_mean(prep.case_C) - device.reference_temperature_C)
        self._nom_jac = None
        self._nom_jac_board = None
        self._nom_jac_theta = None
        self.table_builds = 0
        #: Tables already built, by their exact inputs (:meth:`table`), for this device and grid
        store = {} if tables is None else tables
        self._tables: dict = store.setdefault((id(device), self.grid.tobytes()), (device, {}))[1]
        self._paths = {}
        #: Block sigma used to *score* models (model floor included); see :meth:`set_score_floor`.
        self.S_score = self.S
        #: Channels read through a coarse converter, by index (:meth:`set_converter`)
        self.converter: dict[int, Converter] = {}
        #: Block sigma of the residuals read against the null (noise plus the laws' accuracy beyond the
        #: calibration's temperatures; :meth:`set_law_accuracy`)
        self.S_loc = self.S
        self._curvature = law_curvature(device)
        self._level = np.zeros_like(self.S)

    # ---- devices and tables -------------------------------------------------------------
    def device(self, theta: dict, effects: dict | None = None):
        """Data-sheet device with nominal deviations and the device effects of ``effects``.

        Parameters
        ----------
        theta : dict
        effects : dict, optional

        Returns
        -------
        Device
        """
        dev = apply_nominal(self.device0, theta)
        eff = {k: v for k, v in (effects or {}).items() if k in DEVICE_EFFECTS}
        return apply_effects(dev, eff)

    def table(self, theta: dict, effects: dict | None = None, quad: bool = False,
              rate: bool = False, board: bool = False) -> ResponseTable:
        """Response table of the model at ``(theta, effects)``.

        Parameters
        ----------
        theta, effects : dict
        quad : bool
            Also the quadrature sensitivity.
        rate : bool
            Also the rate sensitivity (always when the record has an applied rate).
        board : bool
            Also the sensitivity to the board standing off the die (a thermal lag's path needs it).

        Returns
        -------
        ResponseTable
        """
        eff = effects or {}
        theta = {k: v for k, v in theta.items() if k not in self._channel_names()}
        rate = rate or self.has_rate
        # a fit often asks again for a table it built before (the nominal point of every effect without a
        # device part, a retried fit's start): kept by the exact inputs when they are all Python numbers
        # (their repr keeps every bit and the sign of zero). The knobs keep their order: apply_nominal applies
        # them in it, and two of them do not commute (f_modes_rel scales the sense frequency, split_Hz adds).
        values = list(theta.values()) + [v for p in eff.values() for v in p.values()]
        key = None
        if all(type(v) in (float, int) for v in values):
            key = repr((list(theta.items()), sorted((n, sorted(p.items())) for n, p in eff.items()), quad, rate,
                        board))
        tab = self._tables.get(key) if key is not None else None
        if tab is None:
            self.table_builds += 1
            tab = response_table(self.device(theta, eff), self.grid, with_rate=rate, with_quad=quad, with_board=board)
            if key is not None:
                self._tables[key] = tab
        return ResponseTable(tab.grid_C, tab.base.copy(), tab.d_rate.copy(), tab.d_quad.copy(),
                             *(None if a is None else a.copy()
                               for a in (tab.d_board, tab.d2_board, tab.d_rate_board, tab.d_quad_board)))

    def _channel_names(self) -> set:
        return {k.name for k, _ in self._chan}

    @property
    def case_dT_K(self) -> np.ndarray:
        """Each block's case temperature from the device's reference (K): what the channels' gain drifts read."""
        return self._dT_b

    def channel_gains(self, theta: dict) -> np.ndarray:
        """``(1 + gain)(1 + tc (T - T0))`` of each channel on each block at ``theta`` (1 where no gain knob acts),
        the quadrature output's times its polarity.

        Parameters
        ----------
        theta : dict

        Returns
        -------
        ndarray, shape (n_blocks, C)
        """
        g = np.ones((self.prep.n_blocks, len(CHANNELS)))
        g[:, CHANNELS.index("quadrature_V")] = self.quadrature_polarity
        for k, c in self._chan:
            if k.kind == "gain":
                g[:, c] += g[:, c] * theta.get(k.name, 0.0)
            elif k.kind == "gain_tc":
                g[:, c] += g[:, c] * theta.get(k.name, 0.0) * self._dT_b
        return g

    def through_channels(self, theta: dict, raw: np.ndarray) -> np.ndarray:
        """Block predictions of the device (``raw``, shape (n, C)) as recorded through the channel knobs.

        Parameters
        ----------
        theta : dict
        raw : ndarray

        Returns
        -------
        ndarray
        """
        y = raw * self.channel_gains(theta)
        for k, c in self._chan:
            if k.kind == "offset":
                y[:, c] += theta.get(k.name, 0.0)
        return y

    def predict(self, theta: dict, effects: dict | None = None) -> np.ndarray:
        """Block predictions of the nominal model at ``theta`` with ``effects`` (their device and path parts).

        Parameters
        ----------
        theta : dict
        effects : dict, optional

        Returns
        -------
        ndarray, shape (n_blocks, C)
        """
        path = self.path({n: v for n, v in (effects or {}).items() if n in PATH_EFFECTS})
        raw = self.table(theta, effects, quad=True, rate=True).evaluate(path["die_b"], path["rate_b"], path["quad_b"])
        return self.through_channels(theta, raw)

    def diff_table(self, t1: ResponseTable, t0: ResponseTable, step: float) -> ResponseTable:
        """(t1 - t0) / step as a table.

        Parameters
        ----------
        t1, t0 : ResponseTable
        step : float

        Returns
        -------
        ResponseTable
        """
        def diff(a, b):
            return None if a is None or b is None else (a - b) / step
        return ResponseTable(self.grid, (t1.base - t0.base) / step, (t1.d_rate - t0.d_rate) / step,
                             np.zeros_like(t0.base), diff(t1.d_board, t0.d_board), diff(t1.d2_board, t0.d2_board),
                             diff(t1.d_rate_board, t0.d_rate_board))

    def nominal_jacobian(self, theta: dict, base: ResponseTable, board: bool = False) -> list:
        """Finite-difference tables of the nominal knobs at ``theta`` (cached after the first call).

        Parameters
        ----------
        theta : dict
        base : ResponseTable
        board : bool, optional
            With the board sensitivities (a thermal lag's path): each knob's column then follows the board
            off the die, against a base table built with them at ``theta`` (``base`` is not used).

        Returns
        -------
        list of ResponseTable
        """
        if board:  # kept per theta: several calibrations (folds) share a fitter
            key = repr(sorted(theta.items()))
            if self._nom_jac_board is None or self._nom_jac_board[0] != key:
                b0 = self.table(theta, board=True)
                self._nom_jac_board = (key, [self.diff_table(
                    self.table({**theta, k.name: theta.get(k.name, 0.0) + k.step}, board=True), b0, k.step)
                    for k in self.knobs.device_knobs])
            return self._nom_jac_board[1]
        if self._nom_jac is None:
            out = []
            for k in self.knobs.device_knobs:
                th = dict(theta)
                th[k.name] = th.get(k.name, 0.0) + k.step
                out.append(self.diff_table(self.table(th), base, k.step))
            self._nom_jac = out
            self._nom_jac_theta = dict(theta)
        return self._nom_jac

    # ---- paths ---------------------------------------------------------------------------
    def path(self, effects: dict | None) -> dict:
        """Block means of the die temperature, the equivalent rate and the quadrature change.

        Parameters
        ----------
        effects : dict or None

        Returns
        -------
        dict
            ``die`` (full rate), ``die_b``, ``rate_b`` (applied + equivalent), ``quad_b``, ``dTdt_b`` (die, K/min),
            ``relax_b`` (t in s for stress relaxation templates), ``board_b`` (the board, i.e. the case, minus the
            die, K; None without a thermal lag).
        """
        key = repr((sorted((effects or {}).items()), self.delay_s))
        if key in self._paths:
            return self._paths[key]
        p = self.prep
        fx = EffectSet({k: v for k, v in (effects or {}).items() if k in PATH_EFFECTS})
        case = p.case_C if not self.delay_s else np.interp(p.t_mid_s + self.delay_s, p.t_mid_s, p.case_C)
        die = fx.die_temperature(p.t_mid_s, case)
        sig = fx.signals(p.t_mid_s, die)
        out = dict(die=die, die_b=p.block_mean(die), rate_b=self.rate_b + p.block_mean(sig["rate_dps"]),
                   quad_b=p.block_mean(sig["quad_rel"]))
        out["dTdt_b"] = p.block_mean(np.gradient(die, p.t_mid_s) * 60.0) if len(die) > 1 else np.zeros(p.n_blocks)
        out["board_b"] = p.block_mean(fx.board_temperature(p.t_mid_s, case) - die) if fx.get("thermal_lag") else None
        if len(self._paths) > 64:
            self._paths.clear()
        self._paths[key] = out
        return out

    # ---- linearisation and solve --------------------------------------------------------
    def nominal_lin(self, theta: dict, base: ResponseTable, path: dict, jac: list | None = None) -> Lin:
        """Linearisation in the nominal knobs at ``theta`` on ``path``.

        Parameters
        ----------
        theta : dict
        base : ResponseTable
        path : dict
        jac : list of ResponseTable, optional

        Returns
        -------
        Lin
        """
        jac = jac if jac is not None else self.nominal_jacobian(theta, base)
        die, rate, quad = path["die_b"], path["rate_b"], path["quad_b"]
        board = path.get("board_b")
        raw = base.evaluate(die, rate, quad, board)
        gain = self.channel_gains(theta)
        y0 = self.through_channels(theta, raw)
        dev = iter(jac)
        cols = []
        for k in self.knobs.knobs:
            if k.on_device:
                j = next(dev)
                cols.append(j.evaluate(die, rate, None, board if j.d_board is not None else None) * gain)
                continue
            if k.kind == "delay":
                # read d later, the temperature the channels saw is the reading plus d dT/dt
                cols.append(np.nan_to_num(base.slope(die)) * (path["dTdt_b"] / 60.0)[:, None] * gain)
                continue
            col = np.zeros_like(raw)
            c = CHANNELS.index(k.channel)
            sign = self.quadrature_polarity if k.channel == "quadrature_V" else 1.0
            col[:, c] = {"gain": sign * raw[:, c], "gain_tc": sign * raw[:, c] * self._dT_b}.get(k.kind, 1.0)
            cols.append(col)
        ks = self.knobs
        x0 = np.array([theta.get(n, 0.0) for n in ks.names])
        for i, k in enumerate(ks.knobs):
            if k.kind == "delay":
                # the path reads the temperature at the model's delay: a ``theta`` at another moves linearly from it
                y0 = y0 + cols[i] * (x0[i] - self.delay_s)
        return Lin(y0, np.stack(cols, axis=-1), ks.names, x0, ks.tolerance.copy(), ks.lo, ks.hi)

    def solve(self, lin: Lin, rows: np.ndarray, Y: np.ndarray | None = None, damping: float = 0.0) -> Solution:
        """Weighted, prior-regularised, bounded linear least squares on the blocks in ``rows``.

        Parameters
        ----------
        lin : Lin
        rows : ndarray of bool
            Blocks to fit.
        Y : ndarray, optional
            Other observations on the same blocks (a null replicate); default the record's.
        damping : float, optional
            Levenberg-Marquardt damping of the step (``damping`` times the normal matrix's diagonal added to it;
            the covariance is the undamped one's).

        Returns
        -------
        Solution
        """
        W = 1.0 / self.S[rows]
        r0 = ((self.Y if Y is None else Y)[rows] - lin.y0[rows]) * W
        A = lin.cols[rows] * W[:, :, None]
        ok = np.isfinite(r0) & self.present[None, :]
        b = r0[ok]
        M = A[ok]
        n = len(b)
        K = len(lin.x0)
        # priors: (x0 + d)/sd ~ N(0, 1)  ->  rows d/sd = -x0/sd
        pr = np.isfinite(lin.prior_sd)
        P = np.zeros((pr.sum(), K))
        P[np.arange(pr.sum()), np.flatnonzero(pr)] = 1.0 / lin.prior_sd[pr]
        pb = -lin.x0[pr] / lin.prior_sd[pr]
        # normal equations (K is small), column-scaled; bounds solved on the K x K Cholesky factor
        MtM, Mtb = M.T @ M, M.T @ b
        PtP, Ptb = P.T @ P, P.T @ pb
        H, g = MtM + PtP, Mtb + Ptb
        Hd = H + damping * np.diag(np.diag(H)) if damping else H
        d, ds, lo, hi = bounded_step(Hd, g, lin.lo - lin.x0, lin.hi - lin.x0)
        x = lin.x0 + d
        cost = float(b @ b - 2 * d @ Mtb + d @ MtM @ d)
        cov0 = scaled_inverse(H)  # H = M.T @ M + P.T @ P
        # the reported covariance: each channel's rows scaled by that channel's own reduced chi-square (when
        # above 1). One channel's misfit (the rate output's flicker wander, an unmodelled disturbance) then
        # widens the knobs that channel determines, not those a well-fitted channel pins
        # (the K degrees of freedom shared out evenly over the channels with data)
        Aok = np.where(ok[:, :, None], A, 0.0)
        nc = ok.sum(axis=0)
        ssr = np.sum(np.where(ok, r0 - Aok @ d, 0.0) ** 2, axis=0)
        red_c = np.maximum(ssr / np.maximum(nc - K / max(int((nc > 0).sum()), 1), 1.0), 1.0)
        Mr = (Aok / np.sqrt(red_c)[None, :, None]).reshape(-1, K)
        return Solution(x, scaled_inverse(Mr.T @ Mr + PtP), cost, n, _free_inverse(H, cov0, ds, lo, hi))

    def set_score_floor(self, table: ResponseTable, die_b: np.ndarray, die_floor_K: float,
                        rel_floor: float = 0.0) -> None:
        """Add a model floor to the scoring sigma of every channel.

        The die temperature of a model with a thermal path (lag, hysteresis) is known to about
        ``die_floor_K`` only, so every channel carries a floor of its temperature sensitivity times
        that; a precise channel (the drive frequency, a thermometer to 1e-4 K) then cannot let a tiny
        systematic misfit buy acceptance. ``rel_floor`` adds a floor proportional to the channel's
        swing over the record.

        Parameters
        ----------
        table : ResponseTable
            The calibrated nominal model.
        die_b : ndarray
            Block die temperatures (the nominal path).
        die_floor_K : float
        rel_floor : float, optional
        """
        slope = np.abs(table.slope(np.nan_to_num(die_b, nan=float(np.nanmean(die_b)))))
        y = table.evaluate(np.nan_to_num(die_b, nan=float(np.nanmean(die_b))))
        swing = np.nanmax(y, axis=0) - np.nanmin(y, axis=0)
        fl2 = (slope * die_floor_K) ** 2 + (rel_floor * swing[None, :]) ** 2
        self.S_score = np.sqrt(self.S ** 2 + fl2)

    def set_law_accuracy(self, table: ResponseTable, die_b: np.ndarray, train: np.ndarray) -> None:
        """Read the residuals against the null (:meth:`residual`) with the laws' accuracy beyond the training window.

        Parameters
        ----------
        table : ResponseTable
            The calibrated nominal model (each channel's level).
        die_b : ndarray
            Block die temperatures.
        train : ndarray of bool
            The calibration's training blocks.
        """
        die = np.nan_to_num(die_b, nan=float(np.nanmean(die_b)))
        self._level = np.abs(table.evaluate(die))
        self.S_loc = np.sqrt(self.S ** 2 + self.law_sd(train) ** 2)

    def law_sd(self, train: np.ndarray) -> np.ndarray:
        """How far the calibrated laws may be off on each block, calibrated on ``train``
        (:data:`fmvmg_sim.uncertainty.LAW_CURVATURE` times the squared distance from the training temperatures).

        Parameters
        ----------
        train : ndarray of bool

        Returns
        -------
        ndarray, shape (n_blocks, C)
        """
        T = self.prep.block_mean(self.prep.case_C)
        Tt = T[train & np.isfinite(T)]
        if not Tt.size or self._curvature == 0.0:
            return np.zeros_like(self.S)
        d = np.nan_to_num(np.maximum(np.maximum(Tt.min() - T, T - Tt.max()), 0.0))
        return self._curvature * self._level * (d ** 2)[:, None]

    def residual(self, pred: np.ndarray, scoring: bool = False, Y: np.ndarray | None = None) -> np.ndarray:
        """(observed - predicted) / sigma per block and channel; NaN for absent channels.

        Parameters
        ----------
        pred : ndarray, shape (n, C)
        scoring : bool, optional
            Divide by the scoring sigma (model floor included) instead of the noise sigma and the laws' accuracy
            beyond the calibration's training window (:meth:`set_law_accuracy`).
        Y : ndarray, optional
            Other observations on the same blocks (a null replicate); default the record's.

        Returns
        -------
        ndarray
        """
        Z = ((self.Y if Y is None else Y) - pred) / (self.S_score if scoring else self.S_loc)
        Z[:, ~self.present] = np.nan
        return Z

    def noise_residual(self, pred: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
        """(observed - predicted) / noise sigma per block and channel (no model floor, no law accuracy); NaN for
        absent channels.

        Parameters
        ----------
        pred : ndarray, shape (n, C)
        Y : ndarray, optional
            Other observations on the same blocks (a null replicate); default the record's.

        Returns
        -------
        ndarray
        """
        Z = ((self.Y if Y is None else Y) - pred) / self.S
        Z[:, ~self.present] = np.nan
        return Z

    def set_converter(self, converter: dict) -> None:
        """Score the channels read through a coarse converter with its expected staircase (:mod:`.converter`).

        Parameters
        ----------
        converter : dict
            ``{channel index: Converter}``; empty to score every channel with the smooth model.
        """
        self.converter = dict(converter)

    def converter_moments(self, pred: np.ndarray, rows: np.ndarray, pred_sd: np.ndarray | None = None) -> dict:
        """Moments of the block means of each channel read through a coarse converter, on ``rows``.

        The prediction passed through the quantiser, dithered by the white noise and blurred by what is common
        to the block: the slow noise, the scoring floors and the prediction's own sd ``pred_sd``
        (:func:`~.converter.staircase_moments`).

        Parameters
        ----------
        pred : ndarray, shape (n, C)
        rows : ndarray of bool
        pred_sd : ndarray, shape (m, C), optional
            The prediction's sd on ``rows`` (parameter uncertainty); zero when not given.

        Returns
        -------
        dict
            ``{channel index: (mean, var)}``, each of shape (m,).
        """
        out = {}
        for c, cv in self.converter.items():
            if not self.present[c]:
                continue
            Ss, S = self.S_score[rows, c], self.S[rows, c]
            sd = np.zeros(len(Ss)) if pred_sd is None else np.nan_to_num(pred_sd[:, c])
            tau_c = np.sqrt(FLOORS[CHANNELS[c]] ** 2 + np.clip(Ss ** 2 - S ** 2, 0.0, None) + cv.slow_V ** 2
                            + sd ** 2)
            n = np.maximum(self.prep.block_counts(CHANNELS[c])[rows], 1)
            m, v = staircase_moments(pred[rows, c] - cv.offset_V, cv.lsb_V, cv.tau_V, tau_c, n)
            out[c] = (m + cv.offset_V, v)
        return out

    def converter_nll(self, moments: dict, rows: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
        """Held-out negative log-likelihood of the channels read through a coarse converter, per block.

        Each block mean is scored against its moments (:meth:`converter_moments`). A block on a plateau is
        known to a tiny fraction of a step, and a model error of a step there would cost without bound, so each
        block's density is a mixture: with weight :data:`~.converter.MISREAD` the level is misread by the
        model, its spread widened by half a step. The density is in units of the scoring sigma, as
        :func:`~.likelihood.nll` is for the smooth channels; blocks are treated as independent (the slow noise
        is in the moments).

        Parameters
        ----------
        moments : dict
            From :meth:`converter_moments` on the same ``rows``.
        rows : ndarray of bool
        Y : ndarray, optional
            Observations on ``rows`` (shape (m, C)) in place of the record's (a candidate's own expected block
            means).

        Returns
        -------
        ndarray, shape (m, C)
            Zero for smooth channels and missing blocks.
        """
        Yr = self.Y[rows] if Y is None else Y
        out = np.zeros(Yr.shape)
        for c, (m, v) in moments.items():
            out[:, c] = np.nan_to_num(misread_nll(Yr[:, c], m, v, self.converter[c].lsb_V, self.S_score[rows, c]))
        return out

    @contextmanager
    def extra_score_floor(self, floor: np.ndarray):
        """Temporarily add ``floor`` (same shape as the blocks) to the scoring sigma, in quadrature.

        Parameters
        ----------
        floor : ndarray, shape (n, C)
        """
        saved = self.S_score
        self.S_score = np.sqrt(saved ** 2 + np.nan_to_num(floor) ** 2)
        try:
            yield
        finally:
            self.S_score = saved


def transient_blocks(prep: Prepared) -> np.ndarray:
    """Blocks in which the applied rate changes, and the block after each.

    Parameters
    ----------
    prep : Prepared

    Returns
    -------
    ndarray of bool, shape (n_blocks,)
    """
    out = np.zeros(prep.n_blocks, bool)
    r = np.asarray(prep.rate_true_dps, dtype=float)
    i = np.flatnonzero(np.abs(np.diff(r)) > 0)
    if i.size:
        b = np.unique(np.concatenate([prep.block[i], prep.block[i + 1]]))
        b = b[b >= 0]
        out[b] = True
        out[np.minimum(b + 1, prep.n_blocks - 1)] = True
    return out


def bounded_step(H: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple:
    """The bounded minimiser ``d`` of ``d^T H d / 2 - g^T d`` with ``lo <= d <= hi`` (normal equations, column-scaled;
    the bounds solved on the K x K Cholesky factor by BVLS only when the free solution leaves them).

    Parameters
    ----------
    H : ndarray, shape (K, K)
        Normal matrix (data and priors).
    g : ndarray, shape (K,)
    lo, hi : ndarray, shape (K,)
        Bounds on the step.

    Returns
    -------
    d : ndarray
        The step.
    ds, lo_s, hi_s : ndarray
        The step and its bounds in the scaled coordinates ``d * sqrt(diag(H))`` (an active bound is where ``ds``
        equals one of them).
    """
    K = len(g)
    scale = np.sqrt(np.clip(np.diag(H), 0, None))
    scale = np.where(scale > 0, scale, 1.0)
    Hs = H / np.outer(scale, scale) + 1e-12 * np.eye(K)
    gs = g / scale
    lo = lo * scale
    hi = hi * scale
    lo = np.where(lo >= hi, hi - 1e-12, lo)
    ds = np.linalg.solve(Hs, gs)
    if np.any(ds < lo) or np.any(ds > hi):
        R = np.linalg.cholesky(Hs).T
        c = np.linalg.solve(R.T, gs)
        ds = lsq_linear(R, c, bounds=(lo, hi), method="bvls").x
    return ds / scale, ds, lo, hi


def effect_bounds(name: str) -> tuple[list, np.ndarray, np.ndarray]:
    """Parameter names and physical bounds of an effect.

    Parameters
    ----------
    name : str

    Returns
    -------
    names, lo, hi
    """
    spec = MODELS[name]
    return list(spec), np.array([p.lo for p in spec.values()]), np.array([p.hi for p in spec.values()])


def _free_inverse(H: np.ndarray, H_inv: np.ndarray, ds: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Inverse of ``H`` over the parameters not at an active bound; zero rows and columns for those at one.

    Parameters
    ----------
    H : ndarray
        Normal matrix.
    H_inv : ndarray
        Its inverse (:func:`scaled_inverse`), returned as it is when no parameter is at a bound.
    ds, lo, hi : ndarray
        Solution and bounds, in the same (scaled) units.

    Returns
    -------
    ndarray
    """
    tol = 1e-9 * np.maximum(hi - lo, 1e-300)
    free = ~((ds - lo <= tol) | (hi - ds <= tol))
    if free.all():
        return H_inv
    out = np.zeros_like(H)
    if free.any():
        out[np.ix_(free, free)] = scaled_inverse(H[np.ix_(free, free)])
    return out


def scaled_inverse(H: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive (semi)definite matrix, robust to very different scales.

    Parameters
    ----------
    H : ndarray

    Returns
    -------
    ndarray
        The inverse; degenerate directions get a large (not zero) variance.
    """
    d = np.sqrt(np.clip(np.diag(H), 1e-150, None))
    Hs = H / np.outer(d, d)
    w, V = np.linalg.eigh(Hs)
    w = np.maximum(w, 1e-14 * max(w.max(), 1e-300))
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        return (V / w) @ V.T / np.outer(d, d)
