"""Closed forms of the physics brief that tests hold the simulator to (bias mechanism, section 2).

The zero-rate output of the open-loop sense chain is quadrature leaking through the phase error
between the sense signal and the demodulation reference, ``Omega_c cos(phi) - Omega_q sin(phi)``
in this wiring (sense mode above the drive mode, sense pickoff sign -1), with
``phi = phi_s + phi_el``: the mechanical sense phase at the die temperature and the electronic
phase drift since the trim at the reference temperature, at the board temperature.
"""

import numpy as np


def electronic_phase_rad(dev, board_C, f_Hz):
    """Phase of the sense chain behind the demodulation reference, from the amplifier and phase-shifter laws.

    Each amplifier lags by atan(G f / GBW(T)); the reference is the drive amplifier's output through the
    RC all-pass (lead pi - 2 atan(w RC(T))) brought to a fixed amplitude, whose fundamental moves by 3/4
    of the all-pass's phase error (the fundamental of v_ps / |(v_x, v_ps)| when v_x and v_ps are off
    quadrature by e is -sin(theta + 3e/4)).
    """
    ci, dT = dev.values["circuit"], np.asarray(board_C) - dev.reference_temperature_C

    def lag(a):
        return np.arctan(abs(a["gain"]) * f_Hz / (a["gbw_Hz"] * (1 + a["gbw_tc_per_K"] * dT)))

    ps = ci["phase_shifter"]
    rc = np.tan(np.pi / 4 - ps["trim_rad"] / 2) / (2 * np.pi * ps["design_frequency_Hz"]) * (1 + ps["rc_tc_per_K"] * dT)
    lead_error = (np.pi - 2 * np.arctan(2 * np.pi * f_Hz * rc)) - np.pi / 2
    return lag(ci["sense_amp1"]) + lag(ci["sense_amp2"]) - lag(ci["drive_amp"]) + 0.75 * lead_error


def zero_rate_output_dps(dev, die_C, board_C):
    """Zero-rate output (deg/s, on the reference temperature's scale factor) at a die and a board temperature.

    ``(Omega_c cos(phi) - Omega_q sin(phi)) SF / SF_0`` with the quadrature rate, the damping coupling
    (``c_q ~ 1/Q_s``) and the sense phase ``atan2(w_s w / Q_s, w_s^2 - w^2)`` from the MEMS laws at the die,
    the electronic phase drift from :func:`electronic_phase_rad` at the board, and the scale factor's
    closed form ``SF ~ Vref G_s1 G_s2 / (G_d dw)`` (physics brief, section 2).
    """
    T0 = dev.reference_temperature_C
    me, th, ci = dev.values["mechanics"], dev.values["thermal"], dev.values["circuit"]

    def state(die, board):
        m = dev.at(die, board_C=board)["mechanics"]
        w, ws = 2 * np.pi * m["f_drive_Hz"], 2 * np.pi * m["f_sense_Hz"]
        dTb = board - T0
        g = np.prod([1 + ci[a]["gain_tc_per_K"] * dTb for a in ("sense_amp1", "sense_amp2")]) / (
            1 + ci["drive_amp"]["gain_tc_per_K"] * dTb)
        sf = (1 + ci["reference"]["vref_tc_per_K"] * dTb) * g / (ws - w)
        return w, ws, m["q_sense"], sf

    w0, _, _, sf0 = state(T0, T0)
    w, ws, q_s, sf = state(float(die_C), float(board_C))
    phi = (np.arctan2(ws * w / q_s, ws ** 2 - w ** 2) + electronic_phase_rad(dev, board_C, w / (2 * np.pi))
           - electronic_phase_rad(dev, T0, w0 / (2 * np.pi)))
    omega_q = me["quadrature_rate_dps"] * (1 + th["quadrature_tc_per_K"] * (die_C - T0))
    omega_c = me["damping_coupling_rate_dps"] * me["q_sense"] / q_s
    return float((omega_c * np.cos(phi) - omega_q * np.sin(phi)) * sf / sf0)
