"""Noise-level effects: a coarser converter (the output's lattice) and extra flicker (the Allan band).

Neither changes the deterministic response, so neither is fitted by the block model:

* ``quantization``: the raw output takes values on a lattice ``k * lsb``; the spacing is read from
  the smallest non-zero steps of ``rate_V`` and checked (most samples on the lattice); a rate output that
  never leaves one level takes the step of the quadrature output, read through the same converter;
* ``flicker_noise``: the Allan deviation of the rate residual in the flicker band (10-300 s) against
  the re-simulated null; the excess variance gives the 1/f level ``h = excess / (2 ln 2)``. The split
  between phase and output flicker is not identifiable from the rate output alone (reported as output).
"""

from __future__ import annotations

import numpy as np

from . import localize as loc
from .data import Prepared, on_lattice
from .forward import IRATE

#: Excess flicker accepted when the held-out and training z-scores exceed these.
FLICKER_Z_HELDOUT = 3.0
FLICKER_Z_TRAIN = 2.0
#: A band excess whose tau^2 part stands this many standard errors above zero, and more than
#: :data:`WANDER_RISE_OVER_FLAT` times as many as its flat part, is a slow wander, not flicker (:func:`band_shape`).
WANDER_Z_RISE = 3.0
WANDER_RISE_OVER_FLAT = 2.0
_FLICKER = (10.0, 300.0)


def quantization_candidate(prep: Prepared, nominal_lsb_V: float) -> dict | None:
    """The quantisation effect if the output's lattice is coarser than the nominal converter's.

    Parameters
    ----------
    prep : Prepared
    nominal_lsb_V : float

    Returns
    -------
    dict or None
        ``{"lsb_V": ..., "on_lattice": ...}``.
    """
    lsb = prep.lattice()[IRATE]
    if lsb > 1.5 * max(nominal_lsb_V, 1e-12):
        return {"lsb_V": lsb, "on_lattice": on_lattice(prep.obs["rate_V"], lsb)}
    return None


def _band(taus, adev_meas, adev_nulls, band, span_s):
    """The band's taus (mask), the nulls' Allan variances there, and the relative sampling variance per tau.

    A few null replicates underestimate the spread where there are few averages: the callers floor it at
    the sampling spread of an Allan variance, ``sqrt(2 / EDF)`` relative, ``EDF ~ span / tau`` (``span``
    defaults to ten times the longest tau)."""
    m = (taus >= band[0]) & (taus <= band[1]) & np.isfinite(adev_meas)
    N = np.array([a[m] ** 2 for a in adev_nulls or [] if len(a) == len(taus)], dtype=float)
    if not m.any():
        return m, N, np.zeros(0)
    span = span_s if span_s is not None else float(taus[-1]) * 10.0
    return m, N, 2.0 / np.maximum(span / taus[m] - 1.0, 1.0)


def band_excess(taus: np.ndarray, adev_meas: np.ndarray, adev_nulls: list, band=_FLICKER,
                span_s: float | None = None) -> tuple[float, float]:
    """Mean excess Allan variance in a band and its z-score against the null spread.

    Parameters
    ----------
    taus, adev_meas : ndarray
    adev_nulls : list of ndarray
    band : tuple, optional
    span_s : float, optional
        Length of the data behind the curves (s); default ten times the longest tau.

    Returns
    -------
    excess_var : float
        (deg/s)^2.
    z : float
    """
    m, N, rel_var = _band(taus, adev_meas, adev_nulls, band, span_s)
    if not m.any() or len(N) < 2:
        return 0.0, 0.0
    meas = np.mean(adev_meas[m] ** 2)
    ref = N.mean(axis=1)
    ex = float(meas - ref.mean())
    sd = float(max(ref.std(ddof=1), np.sqrt(np.mean(rel_var)) * ref.mean(), 0.05 * ref.mean()))
    if not sd > 0:  # no spread to judge against (a null output frozen on one converter level)
        return ex, 0.0
    return ex, ex / (sd * np.sqrt(1 + 1 / len(ref)))


def band_shape(taus: np.ndarray, adev_meas: np.ndarray, adev_nulls: list, band=_FLICKER,
               span_s: float | None = None) -> tuple[float, float]:
    """Split a band's excess Allan variance into a flat (flicker) part and a part rising as tau^2.

    Flicker leaves an excess Allan variance that is flat in tau. A slow deterministic wander (a bias
    that moves over tens of minutes) leaves one that rises as tau^2 for tau well below its period, and
    it can lift the band's mean as much as flicker does. The excess at each tau is fitted as
    ``a + b (tau / tau_max)^2`` by weighted least squares, each point weighted by the null's spread there
    (floored as in :func:`band_excess`).

    Parameters
    ----------
    taus, adev_meas : ndarray
    adev_nulls : list of ndarray
    band : tuple, optional
    span_s : float, optional
        Length of the data behind the curves (s).

    Returns
    -------
    z_flat, z_rise : float
        ``a`` and ``b`` over their standard errors; 0 with fewer than three taus or two nulls.
    """
    m, N, rel_var = _band(taus, adev_meas, adev_nulls, band, span_s)
    if m.sum() < 3 or len(N) < 2:
        return 0.0, 0.0
    ref = N.mean(axis=0)
    e = adev_meas[m] ** 2 - ref
    sd = np.maximum.reduce([N.std(axis=0, ddof=1), np.sqrt(rel_var) * ref, 0.05 * ref]) * np.sqrt(1 + 1 / len(N))
    # taus where the null has no spread (an output frozen on one converter level) cannot be judged
    ok = np.isfinite(sd) & (sd > 0)
    if ok.sum() < 3:
        return 0.0, 0.0
    t = taus[m][ok]
    e, sd = e[ok], sd[ok]
    A = np.column_stack([np.ones(len(t)), (t / t.max()) ** 2]) / sd[:, None]
    coef, *_ = np.linalg.lstsq(A, e / sd, rcond=None)
    se = np.sqrt(np.diag(np.linalg.pinv(A.T @ A)))
    return float(coef[0] / se[0]), float(coef[1] / se[1])


def flicker_level(excess_var_dps2: float) -> float:
    """1/f level from an Allan-variance plateau excess: ``sigma^2 = 2 ln2 h``.

    Parameters
    ----------
    excess_var_dps2 : float

    Returns
    -------
    float
        (deg/s)^2.
    """
    return max(excess_var_dps2, 0.0) / (2 * np.log(2))


class FlickerBand:
    """The flicker band (10-300 s) of a model's rate residual against the null's, on the held-out and training samples.

    The band is read without the slow deterministic signatures a temperature profile can leave
    (:func:`.localize.slow_templates`: an unmodelled gradient term would read as extra flicker), in the record and in
    the null alike. Extra flicker is found when the held-out band stands :data:`FLICKER_Z_HELDOUT` and the training
    band :data:`FLICKER_Z_TRAIN` null standard deviations above the null, and the held-out excess is flat in tau
    rather than rising as tau^2 (:func:`band_shape`: a slow wander).

    Parameters
    ----------
    prep : Prepared
    null_heldout, null_train : list of ndarray
        The null replicates' Allan deviations on the same samples (:func:`.localize.residual_allan`).
    """

    def __init__(self, prep: Prepared, null_heldout: list, null_train: list):
        self.prep = prep
        self.null_heldout, self.null_train = null_heldout, null_train
        self.ho = prep.heldout_mask_samples()
        self.slow = loc.slow_templates(prep)
        quiet = loc.noise_mask(prep)
        self.span_ho = float((self.ho & quiet).sum() * prep.sample_interval_s)
        self.span_tr = float((~self.ho & quiet).sum() * prep.sample_interval_s)

    def judge(self, rate_res_dps: np.ndarray) -> dict:
        """The band of a rate residual.

        Parameters
        ----------
        rate_res_dps : ndarray
            Full-rate rate residual (deg/s).

        Returns
        -------
        dict
            ``excess_heldout``, ``z_heldout``, ``excess_train``, ``z_train`` (excess Allan variance, (deg/s)^2, and
            its z against the null), ``z_flat_heldout``, ``z_rise_heldout`` (:func:`band_shape`), ``raised`` (both
            bands above their thresholds), ``wander`` (raised, but rising as tau^2), ``allan_heldout``
            (``(taus, adev)``).
        """
        p = self.prep
        t_ho, a_ho, _ = loc.residual_allan(p, rate_res_dps, self.ho, self.slow)
        t_tr, a_tr, _ = loc.residual_allan(p, rate_res_dps, ~self.ho, self.slow)
        ex_ho, z_ho = band_excess(t_ho, a_ho, self.null_heldout, span_s=self.span_ho)
        ex_tr, z_tr = band_excess(t_tr, a_tr, self.null_train, span_s=self.span_tr)
        z_flat, z_rise = band_shape(t_ho, a_ho, self.null_heldout, span_s=self.span_ho)
        raised = bool(z_ho > FLICKER_Z_HELDOUT and z_tr > FLICKER_Z_TRAIN)
        wander = bool(raised and z_rise > WANDER_Z_RISE and z_rise > WANDER_RISE_OVER_FLAT * z_flat)
        return {"excess_heldout": ex_ho, "z_heldout": z_ho, "excess_train": ex_tr, "z_train": z_tr,
                "z_flat_heldout": z_flat, "z_rise_heldout": z_rise, "raised": raised, "wander": wander,
                "allan_heldout": (t_ho, a_ho)}
