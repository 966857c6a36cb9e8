"""Step 1: calibrate the nominal model's own parameters on a training window.

Maximum a posteriori over all channels (each weighted by its noise, block level), with the
unit-to-unit tolerances as Gaussian priors, by Gauss-Newton on the quasi-static model. A
parameter whose posterior is not much narrower than its prior, or that is nearly collinear with
another, is flagged as not identifiable from this record (its value is the prior's).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .effort_law import effort_law_start
from .fitting import Fitter, Lin, Solution, scaled_inverse
from ..uncertainty import BOUND_TOLERANCES, KNOBS_BY_NAME
from .parameters import KnobSet, knob_values

#: Posterior/prior standard-deviation ratio above which a parameter is "not identifiable".
NOT_IDENTIFIABLE_RATIO = 0.5
#: A step that lowers the calibration's chi-square by less than this, or by less than this share of it, has found
#: nothing the data can tell: the chi-square is in white block noise, and what is left of it after the first steps is
#: mostly the rate output's slow noise, which a knob combination can follow a little further at every step.
MIN_GAIN_CHI2 = 0.5
MIN_GAIN_REL = 1e-3
#: How far (in tolerances) :func:`release_gains` releases a knob's bound: far enough that the linearised objective's
#: minimum along the knob lies inside it for any knob the record pushes past its tolerance bound.
RELEASE_TOLERANCES = 10.0
#: |correlation| above which a pair is flagged as confounded.
CONFOUND_CORR = 0.95
#: Exponent of the free-molecular gas damping, Q_gas ~ T^-1/2 (physics.md section 2): the Q law's gas-only form.
FREE_MOLECULAR_EXPONENT = 0.5
#: Knobs a calibration from the nominal unit holds at 0 and only the start from the Q law's other form
#: (:func:`law_starts`) frees: beside the gas exponent the solid damping trades the law's slope along a valley,
#: and Levenberg-Marquardt steps from the file's mix crawl along it and stop early, short of the fit the file's
#: mix with its other knobs reaches.
SHAPE_KNOBS = ("q_solid_damping_rel",)


@dataclass
class Calibration:
    """Calibrated nominal parameters.

    Attributes
    ----------
    theta : dict
        Knob deviations from the data-sheet device.
    sd : dict
        Posterior standard deviations.
    identifiable : dict
        Knob -> bool.
    correlated : list
        ``(knob, knob, corr)`` pairs above :data:`CONFOUND_CORR`.
    lin : Lin
        Linearisation at the calibrated point on the nominal path.
    base : ResponseTable
        Table at the calibrated point.
    iterations : int
    solution : Solution
    tolerance : dict
        Each knob's tolerance.
    objective : float
        The calibration's objective at the calibrated unit (weighted squares of the training blocks plus the priors).
    release_gain : dict
        Set by the diagnosis for the calibration it reports (:func:`release_gains`): each knob at its bound
        (:attr:`at_bound`) -> how far the linearised objective falls when that bound alone is
        released (:data:`RELEASE_TOLERANCES`): below the calibration's :func:`resolution` the record does not
        ask for the bound, which holds the knob only because a flat valley of the objective reaches it.
    """

    theta: dict
    sd: dict
    identifiable: dict
    correlated: list
    lin: Lin
    base: object
    iterations: int
    solution: Solution
    tolerance: dict
    objective: float = float("nan")
    release_gain: dict = dataclasses.field(default_factory=dict)

    @property
    def at_bound(self) -> list:
        """Knobs the fit pushed to their bound (BOUND_TOLERANCES x tolerance): the record asks for a unit
        outside its tolerance, itself a sign of an unmodelled effect."""
        return [k for k, v in self.theta.items() if abs(v) >= 0.999 * BOUND_TOLERANCES * self.tolerance[k]]

    @property
    def asked_at_bound(self) -> list:
        """The knobs at their bound that the record asks for there: releasing the bound would lower the objective
        by at least the calibration's :func:`resolution` (:attr:`release_gain`)."""
        return [k for k in self.at_bound if self.release_gain.get(k, np.inf) >= resolution(self.objective)]

    def to_json(self, device=None) -> dict:
        """JSON form: each knob's nominal and calibrated value, its sd and tolerance, and what the record says of it.

        Parameters
        ----------
        device : Device, optional
            The nominal device (for the knobs' values; deviations only without it).

        Returns
        -------
        dict
        """
        pinned, asked = self.at_bound, self.asked_at_bound
        out = {}
        for k, v in self.theta.items():
            knob = KNOBS_BY_NAME[k]
            row = {"value": float(v), "sd": float(self.sd[k]), "identifiable": bool(self.identifiable[k]),
                   "tolerance": self.tolerance[k], "at_bound": k in pinned,
                   "bound_asked_by_record": k in asked,
                   "beyond_tolerance": bool(abs(v) > self.tolerance[k] + 2.0 * self.sd[k]),
                   "group": knob.group, "meaning": knob.meaning}
            if k in self.release_gain:
                row["release_gain"] = float(self.release_gain[k])
            if knob.effect:
                row["effect"] = knob.effect
            if device is not None:
                nom, calv = knob_values(device, k, float(v))
                row.update(nominal=nom, calibrated=calv,
                           sd_calibrated=abs(knob_values(device, k, float(v) + float(self.sd[k]))[1] - calv))
            out[k] = row
        return {"parameters": out, "at_bound": pinned, "at_bound_asked": asked,
                "resolution": resolution(self.objective),
                "not_identifiable": [k for k, ok in self.identifiable.items() if not ok],
                "confounded_pairs": [{"a": a, "b": b, "corr": float(c)} for a, b, c in self.correlated],
                "iterations": self.iterations}


def resolution(objective: float) -> float:
    """The smallest fall of the calibration's objective that says something of the record: :data:`MIN_GAIN_CHI2`,
    or :data:`MIN_GAIN_REL` of the objective where a misfit the model lacks (slow noise, an unmodelled effect)
    dominates it.

    Parameters
    ----------
    objective : float

    Returns
    -------
    float
    """
    return max(MIN_GAIN_CHI2, MIN_GAIN_REL * objective)


def _objective(fitter: Fitter, rows: np.ndarray, theta: dict, base, path: dict) -> float:
    """The calibration's objective with the exact model: weighted squares of the training blocks plus the priors."""
    pred = fitter.through_channels(theta, base.evaluate(path["die_b"], path["rate_b"], path["quad_b"]))
    r = ((fitter.Y - pred) / fitter.S)[rows][:, fitter.present]
    prior = np.array([theta[n] for n in fitter.knobs.names]) / fitter.knobs.tolerance
    return float(np.nansum(r ** 2) + prior @ prior)


def law_starts(knobs: KnobSet, device) -> list:
    """Starting points of the calibration besides the nominal unit: the Q law in its other form.

    The Q law is ``1/Q = 1/Q_gas(T) + 1/Q_solid`` with ``Q_gas ~ T^-n``: its shape, ``ln(s (T/T0)^n + 1 - s)``
    with ``s`` the gas share of the damping, trades its slope between ``n`` and ``s``, and a calibration from the
    device file's mix (a steep gas law beside thermoelastic and anchor losses) stops in the valley on that side:
    its AGC effort (~ 1/Q) then fits the training temperatures with a law of another curvature and misses beyond
    them. The other form is the gas law alone: the solid damping at the lower end of its knob, the free-molecular
    exponent (:data:`FREE_MOLECULAR_EXPONENT`), each within its bounds.

    Parameters
    ----------
    knobs : KnobSet
        The knobs calibrated.
    device : Device
        The nominal device (its gas exponent).

    Returns
    -------
    list of dict
        ``{knob: deviation}`` starts (empty when the device has no solid-damping knob).
    """
    ks = knobs
    if "q_solid_damping_rel" not in ks.names:
        return []
    i = ks.names.index("q_solid_damping_rel")
    start = {"q_solid_damping_rel": float(ks.lo[i])}
    if "q_gas_exponent" in ks.names:
        j = ks.names.index("q_gas_exponent")
        n0 = float(device.values["thermal"]["q_gas_exponent"])
        start["q_gas_exponent"] = float(np.clip(FREE_MOLECULAR_EXPONENT - n0, ks.lo[j], ks.hi[j]))
    return [start]


def release_gains(fitter: Fitter, lin: Lin, rows: np.ndarray, names: list) -> dict:
    """How far the linearised calibration objective falls when the bound of each knob in ``names`` alone is
    released to :data:`RELEASE_TOLERANCES` tolerances.

    Parameters
    ----------
    fitter : Fitter
    lin : Lin
        Linearisation at the calibrated unit.
    rows : ndarray of bool
        Training blocks.
    names : list of str
        Knobs at their bound.

    Returns
    -------
    dict
        Knob -> fall of the objective (weighted squares plus priors; >= 0).
    """
    pr = np.isfinite(lin.prior_sd)

    def objective(l: Lin) -> float:
        s = fitter.solve(l, rows)
        return s.cost + float(np.sum((s.x[pr] / l.prior_sd[pr]) ** 2))

    held = objective(lin)
    tol = fitter.knobs.tolerance
    out = {}
    for name in names:
        i = lin.names.index(name)
        lo, hi = lin.lo.copy(), lin.hi.copy()
        lo[i], hi[i] = -RELEASE_TOLERANCES * tol[i], RELEASE_TOLERANCES * tol[i]
        out[name] = max(held - objective(dataclasses.replace(lin, lo=lo, hi=hi)), 0.0)
    return out


def _hold(lin: Lin, held: list) -> Lin:
    """``lin`` with the knobs at indices ``held`` bounded at their linearisation point."""
    if not held:
        return lin
    lo, hi = lin.lo.copy(), lin.hi.copy()
    lo[held] = hi[held] = lin.x0[held]
    return dataclasses.replace(lin, lo=lo, hi=hi)


def calibrate(fitter: Fitter, rows: np.ndarray, max_iter: int = 25, tol: float = 1e-3,
              refresh: float = 0.05, start: dict | None = None) -> Calibration:
    """Levenberg-Marquardt MAP fit of the nominal knobs on the blocks in ``rows``.

    Each step solves the linearised problem (the knobs' sensitivities as response tables), damped, and is taken
    when the exact model's objective (weighted squares plus the priors) falls; the damping falls after a step taken
    and rises after one refused. The sensitivities are rebuilt wherever a step moves a device knob by more than
    ``refresh`` of its tolerance (a unit far from the device file, a law far from its nominal form, is not linear
    over the whole way).

    Parameters
    ----------
    fitter : Fitter
    rows : ndarray of bool
        Training blocks.
    max_iter : int, optional
        Steps tried, taken or refused.
    tol : float, optional
        Stop when every step is below ``tol`` times its tolerance, or a step lowers the objective by less than
        :data:`MIN_GAIN_CHI2` or :data:`MIN_GAIN_REL` of it.
    refresh : float, optional
    start : dict, optional
        Knob deviations to start from (:func:`law_starts`); default the nominal unit, with the
        :data:`SHAPE_KNOBS` held there.

    Returns
    -------
    Calibration
    """
    knobs = fitter.knobs
    dev = np.array([k.on_device for k in knobs.knobs])
    theta = {n: 0.0 for n in knobs.names}
    theta.update({n: float(v) for n, v in (start or {}).items() if n in theta})
    fitter.delay_s = theta.get("temperature_delay_s", 0.0)
    path = fitter.path(None)
    base = fitter.table(theta)
    jac = fitter.nominal_jacobian(theta, base)
    obj = _objective(fitter, rows, theta, base, path)
    held = [i for i, n in enumerate(knobs.names) if start is None and n in SHAPE_KNOBS]
    lin = _hold(fitter.nominal_lin(theta, base, path, jac), held)
    damping, it = 1e-3, 0
    for it in range(1, max_iter + 1):
        sol = fitter.solve(lin, rows, damping=damping)
        step = (sol.x - lin.x0) / knobs.tolerance
        trial = dict(zip(lin.names, map(float, sol.x)))
        fitter.delay_s = trial.get("temperature_delay_s", 0.0)  # the model reads the temperature that late
        t_base, t_path = fitter.table(trial), fitter.path(None)
        t_obj = _objective(fitter, rows, trial, t_base, t_path)
        if t_obj > obj:  # refused: a shorter, steeper step
            fitter.delay_s = theta.get("temperature_delay_s", 0.0)
            damping *= 3.0
            if damping > 1e6:
                break
            continue
        gained = obj - t_obj
        theta, base, path, obj = trial, t_base, t_path, t_obj
        damping = max(damping / 2.0, 1e-6)
        if np.max(np.abs(step)) < tol or gained < resolution(obj):
            break
        if np.max(np.abs(step[dev]), initial=0.0) > refresh:
            fitter._nom_jac = None  # the sensitivities again, where the unit now is
            jac = fitter.nominal_jacobian(theta, base)
        lin = _hold(fitter.nominal_lin(theta, base, path, jac), held)
    fitter.delay_s = theta.get("temperature_delay_s", 0.0)
    # the linearisation at the calibrated unit: its prediction there is the exact model's, and its solve gives the
    # covariance (not a further step); the cost is the weighted squares there
    lin = fitter.nominal_lin(theta, base, path, jac)
    W = 1.0 / fitter.S[rows]
    r0 = (fitter.Y[rows] - lin.y0[rows]) * W
    ok = np.isfinite(r0) & fitter.present[None, :]
    sol = dataclasses.replace(fitter.solve(lin, rows), x=lin.x0.copy(), cost=float(np.sum(r0[ok] ** 2)))
    sd_post = np.sqrt(np.clip(np.diag(sol.cov), 0, None))
    tolv = knobs.tolerance
    # identifiability from the data alone: posterior without the prior
    A = (lin.cols[rows] * W[:, :, None])
    M = A[ok]
    H = M.T @ M + np.diag(1.0 / tolv ** 2)
    cov_nd = scaled_inverse(H)
    sd_nd = np.sqrt(np.clip(np.diag(cov_nd), 0, None))
    ident = {n: bool(sd_nd[i] < NOT_IDENTIFIABLE_RATIO * tolv[i]) for i, n in enumerate(knobs.names)}
    corr = cov_nd / np.outer(sd_nd, sd_nd)
    pairs = []
    for i in range(len(knobs)):
        for j in range(i + 1, len(knobs)):
            if abs(corr[i, j]) > CONFOUND_CORR:
                pairs.append((knobs.names[i], knobs.names[j], float(corr[i, j])))
    sd = {n: float(sd_post[i]) for i, n in enumerate(knobs.names)}
    return Calibration(theta, sd, ident, pairs, lin, base, it, sol, dict(zip(knobs.names, map(float, tolv))), obj)


def recalibrated(fitter: Fitter, cal, train: np.ndarray, new_fitter) -> tuple:
    """``cal`` (of ``fitter``) or, when it fits the training window better by more than the calibration's resolution
    (:func:`resolution`), the calibration from the Q law's other form (:func:`law_starts`) or
    from the Q law and effort channel that fit the AGC effort alone (:func:`.effort_law.effort_law_start`).

    From the nominal unit, Levenberg-Marquardt steps crawl along the Q law's valley and can stop far from the fit
    these starts reach (a unit whose AGC effort the nominal start leaves thousands of sigmas off).

    Parameters
    ----------
    fitter : Fitter
    cal : Calibration
        ``fitter``'s calibration from the nominal unit.
    train : ndarray of bool
        Training blocks.
    new_fitter : callable
        Returns a fresh Fitter on the same observations, for each start.

    Returns
    -------
    fitter : Fitter
    cal : Calibration
    """
    best = (fitter, cal)
    for start in law_starts(fitter.knobs, fitter.device0) + [effort_law_start(fitter, cal, train)]:
        if start is None:
            continue
        f = new_fitter()
        c = calibrate(f, train, start=start)
        if c.objective < best[1].objective - resolution(best[1].objective):
            best = (f, c)
    return best
