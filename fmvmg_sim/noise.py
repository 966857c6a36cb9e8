"""Noise sequences in physical units: white, flicker (1/f), random walk, quantisation.

Flicker noise is shaped in the frequency domain over the whole record, so its
one-sided PSD ``h_-1 / f`` holds from ``1/T_record`` up to Nyquist (a sum of a few
Markov processes covers only a few decades).
"""

from __future__ import annotations

import numpy as np


def flicker(n: int, fs_Hz: float, h_minus1: float, rng: np.random.Generator) -> np.ndarray:
    """Zero-mean noise with one-sided PSD ``h_-1 / f`` (units^2 / Hz), sampled at ``fs_Hz``.

    Gaussian spectral synthesis: complex Gaussian amplitudes with variance set by the
    target PSD at each FFT bin (Timmer and Koenig 1995), DC removed.

    Parameters
    ----------
    n : int
        Number of samples.
    fs_Hz : float
        Sample rate.
    h_minus1 : float
        Flicker coefficient; the Allan deviation plateau is ``sqrt(2 ln2 h_-1)``.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray
    """
    if n < 2 or h_minus1 <= 0:
        return np.zeros(max(n, 0))
    f = np.fft.rfftfreq(n, 1.0 / fs_Hz)
    psd = np.zeros_like(f)
    psd[1:] = h_minus1 / f[1:]
    # one-sided PSD S -> E|X_k|^2 = S * fs * n / 2 for numpy's unnormalised rfft
    sigma = np.sqrt(psd * fs_Hz * n / 4.0)
    X = sigma * (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f)))
    if n % 2 == 0:
        X[-1] = X[-1].real * np.sqrt(2.0)
    X[0] = 0.0
    return np.fft.irfft(X, n)


def white(n: int, fs_Hz: float, density: float, rng: np.random.Generator) -> np.ndarray:
    """White noise of one-sided density ``density`` (units/sqrt(Hz)), per-sample sigma ``density sqrt(fs/2)``.

    Parameters
    ----------
    n : int
    fs_Hz : float
    density : float
    rng : numpy.random.Generator

    Returns
    -------
    ndarray
    """
    return density * np.sqrt(fs_Hz / 2.0) * rng.standard_normal(n)


def random_walk(n: int, fs_Hz: float, k_per_sqrt_s: float, rng: np.random.Generator) -> np.ndarray:
    """Rate random walk with Allan deviation ``K sqrt(tau/3)``: cumulative sum of steps ``K / sqrt(fs)``.

    Parameters
    ----------
    n : int
    fs_Hz : float
    k_per_sqrt_s : float
        K in units per sqrt(s).
    rng : numpy.random.Generator

    Returns
    -------
    ndarray
    """
    if k_per_sqrt_s <= 0:
        return np.zeros(n)
    return np.cumsum(k_per_sqrt_s / np.sqrt(fs_Hz) * rng.standard_normal(n))


def quantize(x: np.ndarray, lsb: float) -> np.ndarray:
    """Round to a multiple of ``lsb`` (no-op for ``lsb <= 0``).

    Parameters
    ----------
    x : ndarray
    lsb : float

    Returns
    -------
    ndarray
    """
    if lsb <= 0:
        return x
    return np.round(x / lsb) * lsb
