"""Scalar random-walk Kalman filter (paper 000 eqs. 10-14 with Phi = H = 1).

Model x_k = x_{k-1} + w_k (var Q), z_k = x_k + v_k (var R). Noise variances come from the
Allan analysis of the raw rate (compensation.md section 5): R = N^2 fs from the -1/2 region,
Q = K^2 / fs from the +1/2 region (static tests), or Q = (alpha_rms / fs)^2 from an expected
angular acceleration for dynamic use. The gain settles to the steady-state value k of the
discrete Riccati equation, after which the filter is the first-order low-pass
x_k = (1 - k) x_{k-1} + k z_k with cutoff f_c = -fs ln(1 - k) / (2 pi): it is run with a
scalar loop until the gain has converged and ``scipy.signal.lfilter`` after that.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter


def steady_state_gain(q: float, r: float) -> float:
    """Steady-state Kalman gain of the scalar random walk.

    The prior variance solves P = P - P^2 / (P + R) + Q, i.e. P^2 - Q P - Q R = 0.

    Parameters
    ----------
    q, r : float
        Process and measurement noise variances (r > 0).

    Returns
    -------
    float
        k = P / (P + R) with P = (Q + sqrt(Q^2 + 4 Q R)) / 2.
    """
    p = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))
    return p / (p + r)


def cutoff_Hz(gain: float, fs_Hz: float) -> float:
    """-3 dB-equivalent cutoff of the steady-state filter, f_c = -fs ln(1 - k) / (2 pi).

    Parameters
    ----------
    gain : float
        Steady-state gain k in (0, 1).
    fs_Hz : float
        Sampling rate.

    Returns
    -------
    float
        Cutoff in Hz.
    """
    return -fs_Hz * math.log1p(-gain) / (2.0 * math.pi)


def noise_variances(arw_dps_per_rtHz: float, rrw_dps_per_rts: float | None, fs_Hz: float,
                    accel_rms_dps2: float | None = None) -> tuple[float, float]:
    """Q and R of the filter from Allan coefficients.

    Parameters
    ----------
    arw_dps_per_rtHz : float
        White rate noise N in deg/s/sqrt(Hz) (= deg/sqrt(s)).
    rrw_dps_per_rts : float or None
        Rate random walk K in deg/s/sqrt(s) (static use).
    fs_Hz : float
        Sampling rate.
    accel_rms_dps2 : float, optional
        Expected RMS angular acceleration in deg/s^2; when given, Q = (alpha_rms / fs)^2
        replaces K^2 / fs (dynamic use).

    Returns
    -------
    q, r : float
        Per-sample variances in (deg/s)^2.
    """
    r = arw_dps_per_rtHz**2 * fs_Hz
    q = (accel_rms_dps2 / fs_Hz) ** 2 if accel_rms_dps2 is not None else rrw_dps_per_rts**2 / fs_Hz
    return float(q), float(r)


class ScalarKalman:
    """Random-walk Kalman filter for one channel.

    Parameters
    ----------
    q, r : float
        Process and measurement noise variances per sample.
    p0 : float, optional
        Initial state variance (default ``r``); the state starts at the first measurement.
    """

    def __init__(self, q: float, r: float, p0: float | None = None):
        if not (r > 0 and q >= 0):
            raise ValueError(f"need r > 0 and q >= 0, got q={q!r}, r={r!r}")
        self.q, self.r = float(q), float(r)
        self.p0 = float(r if p0 is None else p0)

    @property
    def steady_gain(self) -> float:
        """Steady-state gain k."""
        return steady_state_gain(self.q, self.r)

    def gains(self, n: int, rtol: float = 1e-9) -> np.ndarray:
        """Gain sequence k_1..k_m until it is within ``rtol`` of the steady value (m <= n).

        Parameters
        ----------
        n : int
            Most steps to run.
        rtol : float
            Relative convergence tolerance.

        Returns
        -------
        ndarray
            The transient gains (the filter uses the steady gain after them).
        """
        k_ss, p, out = self.steady_gain, self.p0, []
        for _ in range(n):
            pp = p + self.q
            k = pp / (pp + self.r)
            out.append(k)
            p = (1.0 - k) * pp
            if abs(k - k_ss) <= rtol * k_ss:
                break
        return np.array(out)

    def filter(self, z: np.ndarray) -> np.ndarray:
        """Filtered estimates of the state.

        Parameters
        ----------
        z : ndarray
            Measurements (uniform steps).

        Returns
        -------
        ndarray
            x_hat_k for every k (x_hat_0 = z_0).
        """
        z = np.asarray(z, float)
        out = np.empty_like(z)
        if len(z) == 0:
            return out
        out[0] = z[0]
        ks = self.gains(len(z) - 1)
        x = z[0]
        for i, k in enumerate(ks, start=1):
            x = x + k * (z[i] - x)
            out[i] = x
        m = len(ks) + 1
        if m < len(z):
            k = self.steady_gain
            out[m:], _ = lfilter([k], [1.0, -(1.0 - k)], z[m:], zi=[(1.0 - k) * x])
        return out

