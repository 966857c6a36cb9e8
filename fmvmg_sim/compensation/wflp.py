"""Wavelet transform + forward linear prediction denoiser (WFLP, paper 004 section 3.3).

1. ``pywt.wavedec(x, 'db4', level=4, mode='symmetric')``.
2. The approximation coefficients ``cA`` are replaced by their one-step forward linear
   prediction: an order-``p`` predictor adapted by normalised LMS with a Kwong-Johnston
   variable step ``mu(n+1) = clip(0.97 mu(n) + 4.8e-4 e(n)^2 / var(cA), 1e-4, 0.1)``
   (compensation.md section 5). The white part of ``cA`` is unpredictable, so the
   prediction keeps the slow part.
3. Detail coefficients are soft-thresholded at the universal threshold
   ``sigma * sqrt(2 ln n)``, ``sigma = MAD(cD1) / 0.6745`` (Donoho & Johnstone).
4. ``pywt.waverec`` and trim to the input length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pywt


@dataclass
class NLMSResult:
    """Outcome of :func:`nlms_predict`.

    Parameters
    ----------
    prediction : ndarray
        One-step (a priori) prediction of each sample; the first ``order`` samples,
        which have no full history, are copied from the input.
    weights : ndarray, shape (order,)
        Final predictor weights; ``weights[j]`` multiplies ``x[n - 1 - j]``.
    mean_weights : ndarray, shape (order,)
        Weights averaged over the second half of the series (the LMS estimate of the
        Wiener predictor, free of the final iterate's step noise).
    mu : ndarray
        Step size used at each sample.
    """

    prediction: np.ndarray
    weights: np.ndarray
    mean_weights: np.ndarray
    mu: np.ndarray


def nlms_predict(x, order: int = 8, mu0: float = 0.1, mu_min: float = 1e-4, mu_max: float = 0.1,
                 mu_decay: float = 0.97, mu_gain: float = 4.8e-4, eps: float = 1e-12) -> NLMSResult:
    """Forward linear prediction with normalised LMS and a Kwong-Johnston variable step.

    The series is centred on its mean before prediction and the mean added back.

    Parameters
    ----------
    x : array_like
        Series to predict (1-D).
    order : int, optional
        Predictor order ``p``.
    mu0 : float, optional
        Initial step.
    mu_min, mu_max : float, optional
        Step bounds.
    mu_decay : float, optional
        Step memory (``0.97``).
    mu_gain : float, optional
        Growth of the step per unit of normalised squared error (``4.8e-4``).
    eps : float, optional
        Regulariser of the NLMS normalisation.

    Returns
    -------
    NLMSResult
    """
    x = np.asarray(x, dtype=float)
    mean = float(x.mean())
    xc = (x - mean).tolist()
    var = float(np.var(x)) or 1.0
    w = [0.0] * order
    pred = list(xc)
    mus = [mu0] * len(xc)
    mu = mu0
    half = max(order, len(xc) // 2)
    w_sum = [0.0] * order
    for n in range(order, len(xc)):
        hist = xc[n - order:n][::-1]  # x[n-1], ..., x[n-p]
        xhat = sum(wi * hi for wi, hi in zip(w, hist))
        e = xc[n] - xhat
        pred[n] = xhat
        mus[n] = mu
        step = mu * e / (eps + sum(h * h for h in hist))
        w = [wi + step * hi for wi, hi in zip(w, hist)]
        if n >= half:
            w_sum = [a + b for a, b in zip(w_sum, w)]
        mu = min(max(mu_decay * mu + mu_gain * e * e / var, mu_min), mu_max)
    n_avg = max(len(xc) - half, 1)
    return NLMSResult(prediction=np.asarray(pred) + mean, weights=np.asarray(w),
                      mean_weights=np.asarray(w_sum) / n_avg, mu=np.asarray(mus))


def universal_threshold(detail_finest, n: int) -> tuple[float, float]:
    """Noise level and universal threshold from the finest detail coefficients.

    Parameters
    ----------
    detail_finest : array_like
        ``cD1``, the finest-scale detail coefficients.
    n : int
        Length of the signal being denoised.

    Returns
    -------
    sigma : float
        ``median(|cD1 - median(cD1)|) / 0.6745``.
    threshold : float
        ``sigma * sqrt(2 ln n)``.
    """
    d = np.asarray(detail_finest, dtype=float)
    sigma = float(np.median(np.abs(d - np.median(d)))) / 0.6745
    return sigma, sigma * float(np.sqrt(2.0 * np.log(n)))


def wflp(x, wavelet: str = "db4", level: int = 4, order: int = 8, mode: str = "symmetric",
         predict_approximation: bool = True, threshold_details: bool = True) -> np.ndarray:
    """Denoise a series with WFLP.

    Parameters
    ----------
    x : array_like
        Series to denoise (1-D, evenly sampled).
    wavelet : str, optional
        PyWavelets wavelet name.
    level : int, optional
        Decomposition level (lowered to PyWavelets' maximum for short series).
    order : int, optional
        Forward-linear-prediction order on the approximation coefficients.
    mode : str, optional
        Signal extension mode.
    predict_approximation : bool, optional
        Replace ``cA`` by its prediction (False gives plain wavelet thresholding).
    threshold_details : bool, optional
        Soft-threshold the details (False gives FLP on ``cA`` only).

    Returns
    -------
    ndarray
        Denoised series, same length as ``x``.
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    lev = min(level, pywt.dwt_max_level(n, pywt.Wavelet(wavelet).dec_len))
    if lev < 1:
        return x.copy()
    coeffs = pywt.wavedec(x, wavelet, level=lev, mode=mode)
    if predict_approximation and coeffs[0].size > order:
        coeffs[0] = nlms_predict(coeffs[0], order=order).prediction
    if threshold_details:
        _, thr = universal_threshold(coeffs[-1], n)
        coeffs[1:] = [pywt.threshold(c, thr, mode="soft") for c in coeffs[1:]]
    return pywt.waverec(coeffs, wavelet, mode=mode)[:n]
