"""The PLL drive's settings: the keys of ``[circuit.pll]``, their defaults and temperature laws.

A device or scenario selects the drive loop with ``[circuit.drive] topology``; with ``"pll"`` the
drive force is the AGC output times the output of a controlled oscillator that a phase-locked loop
holds on the drive resonance (docs/model.md, "PLL drive"). Every key of ``[circuit.pll]`` has a
default (:data:`PLL_DEFAULTS`), so a scenario need state only what it changes.
"""

from __future__ import annotations

from .errors import InputError
from .schema import Num

#: Drive-loop topologies a device or scenario may select.
DRIVE_TOPOLOGIES = ("self-oscillating", "pll")

PLL_SCHEMA = {
    "f_free_offset_Hz": Num(-1e5, 1e5), "f_free_tc_per_K": Num(-1e-3, 1e-3),
    "k_vco_Hz_per_V": Num(positive=True), "k_vco_tc_per_K": Num(-0.01, 0.01),
    "kp": Num(lo=0), "ki_per_s": Num(lo=0), "v_min_V": Num(), "v_max_V": Num(),
    "pd_lpf_f_c_Hz": Num(positive=True), "pd_trim": Num(-3.2, 3.2, allow=("auto",)),
}

#: Defaults of ``[circuit.pll]`` (for ``fmvmg_a``: a 36.5 Hz phase loop with 75 degrees of phase margin at
#: the AGC's set-point amplitude; ``fmvmg tune --loop pll`` designs them for any device).
PLL_DEFAULTS = {
    # the oscillator's free-running frequency, relative to the drive resonance at the reference temperature
    "f_free_offset_Hz": 0.0,
    # an NCO clocked by a crystal: +-50 ppm over temperature at most; a VCO on an RC: 100s of ppm/K
    "f_free_tc_per_K": 0.0,
    "k_vco_Hz_per_V": 50.0, "k_vco_tc_per_K": 0.0,
    # loop filter (PI on the low-passed phase detector), its output the tuning voltage
    "kp": 1.0, "ki_per_s": 60.0, "v_min_V": -10.0, "v_max_V": 10.0,
    # the phase detector's low-pass: removes the 2-omega product, 2 kHz (well above the loop's bandwidth)
    "pd_lpf_f_c_Hz": 2000.0,
    # reference rotation cancelling the drive pickoff chain's phase at the reference temperature
    "pd_trim": "auto",
}


def pll_settings(values: dict) -> dict:
    """``[circuit.pll]`` values over their defaults.

    Parameters
    ----------
    values : dict
        The device's (validated) ``circuit.pll`` table, possibly partial or empty.

    Returns
    -------
    dict
        Every key of :data:`PLL_DEFAULTS`.

    Raises
    ------
    ValueError
        The tuning range is empty (``v_min_V >= v_max_V``).
    """
    out = {**PLL_DEFAULTS, **values}
    if not out["v_min_V"] < out["v_max_V"]:
        raise ValueError(f"circuit.pll.v_min_V ({out['v_min_V']}) must be below circuit.pll.v_max_V "
                         f"({out['v_max_V']})")
    return out


def check_pll_values(values: dict, where: str) -> None:
    """Refuse ``[circuit.pll]`` settings that validate key by key but not together.

    Parameters
    ----------
    values : dict
        A device's validated values.
    where : str
        File name for the message.

    Raises
    ------
    InputError
        The tuning range is empty.
    """
    try:
        pll_settings(values.get("circuit", {}).get("pll", {}))
    except ValueError as err:
        raise InputError(str(err), where) from None


def pll_at(values: dict, f_drive_ref_Hz: float, board_delta_K: float) -> dict:
    """The PLL's parameters at a board temperature ``board_delta_K`` from the reference.

    Parameters
    ----------
    values : dict
        The device's ``circuit.pll`` table (defaults fill the rest).
    f_drive_ref_Hz : float
        The drive resonance at the reference temperature (the free-running frequency's origin).
    board_delta_K : float
        Board temperature minus the reference temperature (the oscillator is on the board).

    Returns
    -------
    dict
        ``f_free_Hz``, ``k_vco_Hz_per_V``, ``kp``, ``ki_per_s``, ``v_min_V``, ``v_max_V``,
        ``pd_lpf_f_c_Hz``, ``pd_trim``.
    """
    s = pll_settings(values)
    f_free = (f_drive_ref_Hz + s["f_free_offset_Hz"]) * (1 + s["f_free_tc_per_K"] * board_delta_K)
    return dict(f_free_Hz=float(f_free), k_vco_Hz_per_V=s["k_vco_Hz_per_V"] * (1 + s["k_vco_tc_per_K"] * board_delta_K),
                kp=s["kp"], ki_per_s=s["ki_per_s"], v_min_V=s["v_min_V"], v_max_V=s["v_max_V"],
                pd_lpf_f_c_Hz=s["pd_lpf_f_c_Hz"], pd_trim=s["pd_trim"])
