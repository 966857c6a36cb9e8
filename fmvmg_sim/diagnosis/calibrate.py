"""Step 1: calibrate the nominal model's own parameters on a training window.

Maximum a posteriori over all channels (each weighted by its noise, block level), with the
unit-to-unit tolerances as Gaussian priors, by Gauss-Newton on the quasi-static model. A
parameter whose posterior is not much narrower than its prior, or that is nearly collinear with
another, is flagged as not identifiable from this record (its value is the prior's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fitting import Fitter, Lin, Solution, scaled_inverse
from .parameters import BOUND_TOLERANCES, KNOBS_BY_NAME, NOMINAL_KNOBS

#: Posterior/prior standard-deviation ratio above which a parameter is "not identifiable".
NOT_IDENTIFIABLE_RATIO = 0.5
#: |correlation| above which a pair is flagged as confounded.
CONFOUND_CORR = 0.95


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
    """

    theta: dict
    sd: dict
    identifiable: dict
    correlated: list
    lin: Lin
    base: object
    iterations: int
    solution: Solution

    @property
    def at_bound(self) -> list:
        """Knobs the fit pushed to their bound (BOUND_TOLERANCES x tolerance): the record asks for a unit
        outside its tolerance, itself a sign of an unmodelled effect."""
        return [k for k, v in self.theta.items() if abs(v) >= 0.999 * BOUND_TOLERANCES * KNOBS_BY_NAME[k].tolerance]

    def to_json(self) -> dict:
        """JSON form.

        Returns
        -------
        dict
        """
        pinned = self.at_bound
        return {"parameters": {k: {"value": float(v), "sd": float(self.sd[k]), "identifiable": bool(self.identifiable[k]),
                                   "tolerance": KNOBS_BY_NAME[k].tolerance, "at_bound": k in pinned}
                               for k, v in self.theta.items()},
                "at_bound": pinned,
                "confounded_pairs": [{"a": a, "b": b, "corr": float(c)} for a, b, c in self.correlated],
                "iterations": self.iterations}


def calibrate(fitter: Fitter, rows: np.ndarray, max_iter: int = 6, tol: float = 1e-3) -> Calibration:
    """Gauss-Newton MAP fit of the nominal knobs on the blocks in ``rows``.

    Parameters
    ----------
    fitter : Fitter
    rows : ndarray of bool
        Training blocks.
    max_iter : int, optional
    tol : float, optional
        Stop when every step is below ``tol`` times its tolerance.

    Returns
    -------
    Calibration
    """
    theta = {k.name: 0.0 for k in NOMINAL_KNOBS}
    path = fitter.path(None)
    base = fitter.table(theta)
    jac = fitter.nominal_jacobian(theta, base)
    it = 0
    for it in range(1, max_iter + 1):
        lin = fitter.nominal_lin(theta, base, path, jac)
        sol = fitter.solve(lin, rows)
        step = np.abs(sol.x - lin.x0) / np.array([k.tolerance for k in NOMINAL_KNOBS])
        theta = dict(zip(lin.names, map(float, sol.x)))
        base = fitter.table(theta)
        if np.max(step) < tol:
            break
        if it == 1:  # the sensitivities again, at the first estimate (units are far from the data sheet)
            fitter._nom_jac = None
            jac = fitter.nominal_jacobian(theta, base)
    lin = fitter.nominal_lin(theta, base, path, jac)
    sol = fitter.solve(lin, rows)
    theta = dict(zip(lin.names, map(float, sol.x)))
    sd_post = np.sqrt(np.clip(np.diag(sol.cov), 0, None))
    tolv = np.array([k.tolerance for k in NOMINAL_KNOBS])
    # identifiability from the data alone: posterior without the prior
    W = 1.0 / fitter.S[rows]
    A = (lin.cols[rows] * W[:, :, None])
    ok = np.isfinite((fitter.Y[rows] - lin.y0[rows]) * W) & fitter.present[None, :]
    M = A[ok]
    H = M.T @ M + np.diag(1.0 / tolv ** 2)
    cov_nd = scaled_inverse(H)
    sd_nd = np.sqrt(np.clip(np.diag(cov_nd), 0, None))
    ident = {k.name: bool(sd_nd[i] < NOT_IDENTIFIABLE_RATIO * k.tolerance) for i, k in enumerate(NOMINAL_KNOBS)}
    corr = cov_nd / np.outer(sd_nd, sd_nd)
    pairs = []
    for i in range(len(NOMINAL_KNOBS)):
        for j in range(i + 1, len(NOMINAL_KNOBS)):
            if abs(corr[i, j]) > CONFOUND_CORR:
                pairs.append((NOMINAL_KNOBS[i].name, NOMINAL_KNOBS[j].name, float(corr[i, j])))
    sd = {k.name: float(sd_post[i]) for i, k in enumerate(NOMINAL_KNOBS)}
    return Calibration(theta, sd, ident, pairs, lin, base, it, sol)
