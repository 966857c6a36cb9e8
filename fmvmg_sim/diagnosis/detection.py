"""The smallest effect a record would attribute: each library effect's detection limit on this record.

A verdict of "none" says what the record does not show; a user also needs to know what it could not have shown.
For each deterministic library effect this module gives the size at which the attribution's acceptance criteria
(:data:`.criteria.CRITERIA`, :meth:`.heldout.Scorer.folds_ok`) would pass with probability :data:`POWER` were
the effect there: the minimum detectable effect (MDE).

The limit is read at the calibrated unit, from the record's design (its temperature profile, applied rate, noise and
folds), never from a fit of the effect. Method, one amplitude at a time:

* **The effect's column**: its response per unit amplitude at the calibrated device (:class:`.model.EffectModel`'s
  linearisation with every amplitude at 0 and the shape parameters at :data:`REFERENCE`). The thermal lag's size is
  its time constant: its column is the response's temperature slope times the die's temperature rate, the response
  per second of a short lag, beside the offset it is fitted with.
* **Refitted within the bounds** (:class:`_Refit`): on each fold's training blocks the nominal knobs and the
  effect's other parameters refit around the calibrated prediction plus ``a`` times the column (weighted least
  squares with their priors and bounds, as :meth:`.fitting.Fitter.solve`), and take what they can of it. A drift
  the knobs can mimic (a quadrature or mode-split drift beside the quadrature and split knobs) is absorbed until a
  knob reaches its tolerance bound, and shows beyond it; the limit of such an effect is set there. What is left is
  the signature the fold's held-out blocks see, scored in nats (:func:`.likelihood.expected_gain` under the null's
  noise model).
* **The criteria, simulated** (:func:`pass_rate`, :data:`DRAWS` draws with common random numbers):

  - on the training window the amplitude's estimate and the likelihood ratio move together: parameter
    significance ``|z + zeta| > PARAM_Z_MIN`` (``z`` the amplitude over its standard error with the knobs at a
    bound held, as :attr:`.fitting.Solution.cov_noise` holds them; the lag has no such criterion) and dBIC,
    ``(sqrt(2 I_train) + zeta)^2 + chi^2_{k-1}`` (``k`` parameters fitted) above ``k ln n - DELTA_BIC_MAX``, with
    one standard normal ``zeta``;
  - each fold's held-out total is ``I_k - c_k d_k^2 + sqrt(2 I_k) eta_k``: what the effect carries there, less what
    its refit's estimation error costs (``d_k`` standard normal, ``c_k = I_k / (a^2 F_k)``), plus the held-out
    noise; a fold passes when it exceeds ``FOLD_MIN_NATS`` and ``1.96 sqrt(2 I_k)`` (its interval's lower end above
    zero), and the folds carry the effect as :meth:`~.heldout.Scorer.folds_ok` asks (enough passing folds, the one
    testable fold, or folds that carry it together);
  - the pooled held-out interval excludes zero.

  The limit is where the pass rate reaches :data:`POWER` (bisection on the logarithm of ``a``), the larger of the
  two signs of the column (the knobs may have room for one and not the other, and a calibration that absorbed part
  of an effect already holds a knob at its bound on that effect's side). Beyond 100 times the
  effect's physical bound it is reported as not detectable. The bounds criterion and the look-alike rules are not
  simulated, and the gains are read under the noise model, not through a coarse converter's staircase.

Because the knobs are read at their calibrated values, an effect already in the record that the calibration has
partly absorbed moves them towards a bound and can lower the limit a little (the test suite checks it stays within
25 % of the null record's). Checked on labelled cases by ``fmvmg diagnose-benchmark`` (``detection_claim``).

What it does not promise: that the effect is named first (a look-alike can explain the same gap: the ambiguity set
says so), nor anything of the noise-level effects (extra flicker is judged by its Allan band, a coarser converter
by the output's lattice).
"""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

from ..effects import MODELS
from .attribution import DETERMINISTIC
from .criteria import DELTA_BIC_MAX, PARAM_Z_MIN
from .heldout import (FOLD_CONSISTENCY_REL, FOLD_INFO_NATS, FOLD_JOIN_NATS, FOLD_MIN_NATS, FOLDS_COMBINED_Z,
                      Scorer)
from .fitting import DEVICE_EFFECTS, bounded_step
from .likelihood import expected_gain, fit_params
from .model import EffectModel

#: Probability of attribution at the reported detection limit.
POWER = 0.9

#: Parameters at which an amplitude's limit is given, each at the geometric middle of its prior range
#: (``sqrt(lo * hi)``): the shape parameters of hysteresis and relaxation, and the feedthrough's temperature
#: coefficient (its size is its capacitance; the coefficient only tilts it). The lag's own size is its time constant.
REFERENCE = {"thermal_hysteresis": {"width_K": float(np.sqrt(5.0 * 20.0))},
             "stress_relaxation": {"tau_h": float(np.sqrt(1.0 * 24.0))},
             "feedthrough": {"tc_per_K": float(np.sqrt(1e-4 * 5e-4))}}

#: The parameters whose limits are given, where not every amplitude is one (the others are refitted beside them).
SIZES = {"feedthrough": ("c_ft_fF",), "thermal_lag": ("tau_s",)}

#: The nonlinear parameter of the path effects given at a reference value.
NONLINEAR_PARAM = {"thermal_hysteresis": "width_K", "stress_relaxation": "tau_h"}

#: Draws of the statistics' sampling distributions per power evaluation, and their seed.
DRAWS = 4000
DRAWS_SEED = 20261201

#: Two-sided 95 % normal quantile: a bootstrap interval's lower end above zero, approximately.
Z_CI = float(norm.ppf(0.975))


class _Refit:
    """The nominal knobs (and the effect's other parameters) refitted within their bounds on one training window,
    beside an amplitude ``a`` of one effect column: what they absorb of it, and the nats of what is left.

    The refit is :meth:`.fitting.Fitter.solve`'s (weighted least squares with the knobs' priors, bounded by
    :func:`.fitting.bounded_step`), on the
    calibrated prediction plus ``a`` times the column; its normal matrix is built once, so each amplitude costs a
    K x K solve. While no bound is active, what is left is ``a`` times the column's projection off the knobs; a
    knob at its bound (the unit's tolerance) absorbs no more, and the rest of the signature shows.

    Parameters
    ----------
    lin : Lin
        The knobs, the effect's columns, at the calibrated point.
    j : int
        The column whose amplitude is varied.
    fitter : Fitter
    rows : ndarray of bool
        The training window.
    base : ndarray, shape (n, C)
        The calibrated prediction.
    out_rows : ndarray of bool
        The blocks whose nats are read (the fold's scored blocks, or the training window).
    par : list
        The noise model the nats are read under (:func:`.likelihood.expected_gain`).
    """

    def __init__(self, lin, j: int, fitter, rows: np.ndarray, base: np.ndarray, out_rows: np.ndarray, par: list):
        K = len(lin.names)
        self.j, self.par = j, par
        self.o = np.array([i for i in range(K) if i != j], int)
        cols = np.nan_to_num(lin.cols)
        W = 1.0 / fitter.S[rows]
        ok = np.isfinite(fitter.Y[rows]) & fitter.present[None, :] & np.isfinite(W)
        W = np.nan_to_num(W)
        M = (cols[rows] * W[:, :, None])[ok]
        b0 = ((base - lin.y0)[rows] * W)[ok]
        bu = (cols[rows][:, :, j] * W)[ok]
        prec = np.where(np.isfinite(lin.prior_sd), 1.0 / np.where(np.isfinite(lin.prior_sd), lin.prior_sd, 1.0) ** 2,
                        0.0)
        pb = np.where(np.isfinite(lin.prior_sd), -lin.x0, 0.0) * prec
        self.Hfull = M.T @ M + np.diag(prec)
        Mo = M[:, self.o]
        self.H = self.Hfull[np.ix_(self.o, self.o)]
        self.g0 = Mo.T @ b0 + pb[self.o]
        self.gu = Mo.T @ bu
        self.lo, self.hi = lin.lo[self.o] - lin.x0[self.o], lin.hi[self.o] - lin.x0[self.o]
        self.d0, _ = self._solve(0.0)
        # the blocks read, normalised by the scoring sigma (zero where a channel or block has no data)
        wz = np.where(np.isfinite(fitter.Y[out_rows]) & fitter.present[None, :],
                      1.0 / fitter.S_score[out_rows], 0.0)
        self.uz = cols[out_rows][:, :, j] * wz
        self.Oz = cols[out_rows][:, :, self.o] * wz[:, :, None]

    def _solve(self, a: float) -> tuple[np.ndarray, np.ndarray]:
        """Bounded solution (deviation from the linearisation point) and the mask of parameters at a bound."""
        d, ds, lo, hi = bounded_step(self.H, self.g0 + a * self.gu, self.lo, self.hi)
        active = (ds <= lo + 1e-9 * np.maximum(1.0, np.abs(lo))) | (ds >= hi - 1e-9 * np.maximum(1.0, np.abs(hi)))
        return d, active

    def at(self, a: float) -> tuple[float, float]:
        """Nats of what is left of amplitude ``a`` after the refit, and the amplitude's Fisher information with the
        parameters at a bound held (as :attr:`.fitting.Solution.cov_noise` holds them).

        Parameters
        ----------
        a : float

        Returns
        -------
        nats : float
            On the blocks read, under the noise model.
        F : float
            On the training window, under the fitting weights.
        """
        d, active = self._solve(a)
        nats = expected_gain(a * self.uz - self.Oz @ (d - self.d0), self.par)
        free = self.o[~active]
        Hoo = self.Hfull[np.ix_(free, free)]
        h = self.Hfull[free, self.j]
        F = float(self.Hfull[self.j, self.j])
        if len(free):
            sc = np.sqrt(np.clip(np.diag(Hoo), 1e-300, None))
            F -= float((h / sc) @ np.linalg.solve(Hoo / np.outer(sc, sc) + 1e-12 * np.eye(len(sc)), h / sc))
        return nats, max(F, 0.0)


def _draws(n_folds: int, k: int, n: int = None) -> dict:
    """The standard random numbers every power evaluation shares (common random numbers: the power is then a smooth,
    deterministic function of the amplitude, and the bisection's steps compare like with like)."""
    n = n or DRAWS
    rng = np.random.default_rng(DRAWS_SEED)
    return {"zeta": rng.standard_normal(n), "chi2_rest": rng.chisquare(k - 1, n) if k > 1 else np.zeros(n),
            "delta": rng.standard_normal((n, n_folds)), "eta": rng.standard_normal((n, n_folds))}


def pass_rate(z_mean: float | None, I_train: float, k: int, n: int, folds: list, folds_needed: int,
              draws: dict | None = None) -> float:
    """Probability that an effect passes the acceptance criteria (module docstring), from what it carries.

    Simulated from the statistics' sampling distributions, the criteria applied as
    :data:`.criteria.CRITERIA` and :meth:`.heldout.Scorer.folds_ok` apply them.

    Parameters
    ----------
    z_mean : float or None
        The amplitude over its standard error on the training window (None: no significance criterion).
    I_train : float
        Nats the effect carries on the training window.
    k, n : int
        Parameters fitted and data rows on the training window (the BIC penalty).
    folds : list of (I, c)
        Per scored fold: nats the effect carries on its held-out blocks, and the nats its refit loses per unit
        squared standard error of its amplitude (``i / F`` for a linear signature ``I = i a^2`` whose training window
        holds ``F``; the fold's total is ``I - c d^2 + sqrt(2 I) eta``, ``d`` and ``eta`` standard normal).
    folds_needed : int
    draws : dict, optional
        From :func:`_draws` (default: drawn here, the same every call).

    Returns
    -------
    float
    """
    d = draws or _draws(len(folds), k)
    ok = np.ones(len(d["zeta"]), bool)
    # the training window: the amplitude's estimate and the likelihood ratio move together
    if z_mean is not None:
        ok &= np.abs(z_mean + d["zeta"]) > PARAM_Z_MIN
    chi2 = (np.sqrt(2.0 * max(I_train, 0.0)) + d["zeta"]) ** 2 + d["chi2_rest"]
    ok &= chi2 > k * np.log(max(n, 2)) - DELTA_BIC_MAX
    if not folds:
        return 0.0
    info = np.array([max(f[0], 0.0) for f in folds], float)
    cost = np.array([f[1] for f in folds], float)
    # each fold's held-out total: what the effect earns, less what its refit's estimation error costs, plus noise
    with np.errstate(invalid="ignore"):
        T = info - (d["delta"] ** 2) * cost + np.sqrt(2.0 * info) * d["eta"]
    T = np.where(np.isfinite(T), T, -np.inf)
    sd = np.sqrt(2.0 * info)
    passed = (T >= FOLD_MIN_NATS) & (T > Z_CI * sd)
    consistent = np.abs(T - info) <= 3.0 * sd + FOLD_CONSISTENCY_REL * info

    def together(sel):
        if sel.sum() < 2:
            return np.zeros(len(T), bool)
        Ts = T[:, sel]
        return (np.all(consistent[:, sel] & (Ts > 0), axis=1)
                & (Ts.sum(axis=1) >= FOLDS_COMBINED_Z * np.sqrt(2.0 * info[sel].sum())))
    testable = info >= FOLD_INFO_NATS
    fok = passed.sum(axis=1) >= folds_needed
    if testable.sum() == 1:
        t = int(np.flatnonzero(testable)[0])
        fok |= passed[:, t] & consistent[:, t]
    fok |= together(testable) | together(info >= FOLD_JOIN_NATS)
    # the pooled held-out interval excludes zero
    pooled = T.sum(axis=1) > Z_CI * np.sqrt(2.0 * info.sum())
    return float(np.mean(ok & fok & pooled))


def _solve_mde(pw, hi_bound: float, target: float = POWER) -> float | None:
    """Smallest amplitude with ``pw(a) >= target`` below ``100 x hi_bound``, by bisection on log a (None: none)."""
    top = 100.0 * hi_bound
    if pw(top) < target:
        return None
    lo, hi = top * 1e-9, top
    if pw(lo) >= target:
        return lo
    for _ in range(60):
        mid = np.sqrt(lo * hi)
        if pw(mid) >= target:
            hi = mid
        else:
            lo = mid
        if hi / lo < 1.0 + 1e-3:
            break
    return float(hi)


def _lag_column(fitter, cal) -> np.ndarray:
    """Response per second of a short thermal lag: the die-temperature slope (the board stays on the case) times
    the die's rate (K/s)."""
    path = fitter.path(None)
    return -np.nan_to_num(_die_slope(fitter, cal, path["die_b"])) * (path["dTdt_b"] / 60.0)[:, None]


def _die_slope(fitter, cal, die_b: np.ndarray) -> np.ndarray:
    """Slope of the calibrated response in the die temperature alone, the board held on the case."""
    return fitter.table(cal.theta, board=True).die_slope(die_b)


def effect_limits(scorer: Scorer, name: str) -> dict:
    """Detection limits of one deterministic effect's parameters on the scorer's record.

    Parameters
    ----------
    scorer : Scorer
    name : str
        A deterministic library effect.

    Returns
    -------
    dict
        ``params``: ``{param: smallest |value| attributed with probability POWER, or None beyond 100 x its
        bound}``; ``beyond_bound``: parameters whose limit exceeds their physical bound (not detectable here);
        ``at``: the nonlinear parameters it is given at.
    """
    f, cal = scorer.f, scorer.cal
    ref = dict(REFERENCE.get(name, {}))
    em = EffectModel(f, cal, [name])
    if name in DEVICE_EFFECTS:
        # sizes from zero: the amplitudes at 0, the shape parameters at their reference
        em.values[name] = {p: ref.get(p, 0.0) for p in MODELS[name]}
    em._build_safely()
    K0 = len(f.knobs)
    if name == "thermal_lag":
        # the unlagged path, the lag's own column and the offset it is fitted with
        path = f.path(None)
        lin = f.nominal_lin(em.theta, em.base, path, em.cal_jac())
        die = path["die_b"]
        C = np.stack([_die_slope(f, cal, die), _lag_column(f, cal)], axis=-1)
        off, tau = MODELS[name]["offset_K"], MODELS[name]["tau_s"]
        lin = type(lin)(lin.y0, np.concatenate([lin.cols, C], axis=-1),
                        list(lin.names) + ["thermal_lag.offset_K", "thermal_lag.tau_s"],
                        np.concatenate([lin.x0, [0.0, 0.0]]),
                        np.concatenate([lin.prior_sd, [3.0 * off.prior[1], np.nan]]),
                        np.concatenate([lin.lo, [off.lo, 0.0]]), np.concatenate([lin.hi, [off.hi, tau.hi]]))
        targets = {"tau_s": len(lin.names) - 1}
    else:
        lin = em._lin({n: ref[NONLINEAR_PARAM[n]] for n in em.names if n in NONLINEAR_PARAM})
        targets = {nm.split(".")[1]: i for i, nm in enumerate(lin.names)
                   if i >= K0 and nm.split(".")[1] in SIZES.get(name, MODELS[name])}
    base = cal.lin.predict(cal.solution.x)
    par = scorer.noise_params or fit_params(f.residual(scorer.nominal_train_pred, scoring=True)[scorer.train])
    n_rows = int(np.isfinite(f.residual(scorer.nominal_train_pred, scoring=True)[scorer.train]).sum())
    k = len(MODELS[name])
    out, beyond = {}, []
    for p, j in targets.items():
        refit_tr = _Refit(lin, j, f, scorer.train, base, scorer.train, par)
        refit_k = [_Refit(lin, j, f, fd["train"], base, fd["test"], par) for fd in scorer.folds]
        draws = _draws(len(refit_k), k)

        def pw(a, refit_tr=refit_tr, refit_k=refit_k, draws=draws):
            # a signed amplitude; its Fisher information and nats do not depend on the sign but through the bounds
            nats_tr, F = refit_tr.at(a)
            folds = []
            for rf in refit_k:
                nats_k, F_k = rf.at(a)
                folds.append((nats_k, nats_k / (a * a * F_k) if F_k > 0 else np.inf))
            z = None if name == "thermal_lag" else abs(a) * np.sqrt(F)
            return pass_rate(z, nats_tr, k, n_rows, folds, scorer.folds_needed, draws)
        spec = MODELS[name][p]
        hi = max(abs(spec.lo), abs(spec.hi))
        # both signs, the larger limit: the knobs may have room to absorb one and not the other. For a signed
        # parameter that is an effect of either sign; for one that cannot change sign (a feedthrough capacitance) the
        # mirrored column stands in for the knobs' room on their other side. A calibration that has already absorbed
        # part of an effect holds a knob at its bound on the effect's side, and the physical sign alone then reads
        # a limit far too small
        signs = (1.0, -1.0)
        lims = [_solve_mde(lambda a, sg=sg: pw(sg * a), hi) for sg in signs]
        mde = None if any(v is None for v in lims) else max(lims)
        out[p] = mde
        if mde is None or mde > hi:
            beyond.append(p)
    return {"params": out, "beyond_bound": beyond, "at": ref}


def detection_limits(scorer: Scorer, names: tuple = DETERMINISTIC) -> dict:
    """Detection limits of every deterministic library effect on the scorer's record.

    Parameters
    ----------
    scorer : Scorer
    names : tuple of str, optional

    Returns
    -------
    dict
        ``{effect: effect_limits(...)}``; an effect whose linearisation leaves the model's domain carries
        ``error`` instead.
    """
    out = {}
    for n in names:
        try:
            out[n] = effect_limits(scorer, n)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            out[n] = {"params": {}, "beyond_bound": [], "at": {}, "error": f"{type(exc).__name__}: {exc}"}
    return out
