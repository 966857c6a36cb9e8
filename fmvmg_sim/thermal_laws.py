"""Temperature laws of the device and its electronics (physics brief section 2).

Pure functions of temperature: both engines, the tuning tools and the effects call
them, so a law is written once.
"""

from __future__ import annotations

import numpy as np

KELVIN = 273.15


def frequency_Hz(f0_Hz, dT_K, a1_per_K, a2_per_K2):
    """``f = f0 (1 + a1 dT + a2 dT^2)`` (linear TCF with a small quadratic term).

    Parameters
    ----------
    f0_Hz : float
        Frequency at the reference temperature.
    dT_K : float or ndarray
        Temperature minus the reference.
    a1_per_K, a2_per_K2 : float
        Coefficients.

    Returns
    -------
    float or ndarray
    """
    return f0_Hz * (1.0 + a1_per_K * dT_K + a2_per_K2 * dT_K ** 2)


def quality_factor(q0, T_C, T0_C, q_ted, q_anchor, gas_exponent):
    """``1/Q = 1/Q_gas(T) + 1/Q_TED + 1/Q_anchor`` with ``Q_gas ~ T^-n`` (T in kelvin).

    ``Q_gas`` at the reference temperature is whatever makes the total equal ``q0``.

    Parameters
    ----------
    q0 : float
        Total Q at the reference temperature.
    T_C, T0_C : float or ndarray
        Temperature and reference temperature in degC.
    q_ted, q_anchor : float
        Thermoelastic and anchor Q (temperature independent here).
    gas_exponent : float
        n in ``Q_gas ~ T^-n``.

    Returns
    -------
    float or ndarray
    """
    inv_gas0 = 1.0 / q0 - 1.0 / q_ted - 1.0 / q_anchor
    if np.any(inv_gas0 <= 0):
        raise ValueError("q_ted and q_anchor must exceed the total Q")
    ratio = (np.asarray(T_C) + KELVIN) / (T0_C + KELVIN)
    inv_gas = inv_gas0 * ratio ** gas_exponent
    return 1.0 / (inv_gas + 1.0 / q_ted + 1.0 / q_anchor)


def quality_factor_law(q0, T_C, T0_C, q_ted, q_anchor, gas_exponent, extra_tc_per_K=0.0, curvature_per_K2=0.0):
    """:func:`quality_factor` with an extra drift and a curvature on ``ln Q``: ``exp(tc dT + c dT^2)`` times it.

    Acting on ``ln Q`` keeps Q positive at any temperature whatever their size (a factor ``1 + tc dT`` would cross
    zero within the extra drift's range).

    Parameters
    ----------
    q0, T_C, T0_C, q_ted, q_anchor, gas_exponent
        As :func:`quality_factor`.
    extra_tc_per_K : float, optional
        The extra drift of ``ln Q`` (the ``q_factor_drift`` effect).
    curvature_per_K2 : float, optional
        The curvature of ``ln Q``.

    Returns
    -------
    float or ndarray
    """
    dT = np.asarray(T_C) - T0_C
    return quality_factor(q0, T_C, T0_C, q_ted, q_anchor, gas_exponent) * np.exp(
        extra_tc_per_K * dT + curvature_per_K2 * dT * dT)


def linear_tc(value0, dT_K, tc_per_K):
    """``value0 (1 + tc dT)``: a first-order temperature coefficient.

    Parameters
    ----------
    value0 : float
    dT_K : float or ndarray
    tc_per_K : float

    Returns
    -------
    float or ndarray
    """
    return value0 * (1.0 + tc_per_K * dT_K)
