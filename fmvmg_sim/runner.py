"""Run a scenario with the engine its fidelity asks for, and summarise it."""

from __future__ import annotations

import numpy as np

from . import thermal_laws as law
from .averaged import scale_factor_V_per_dps, steady_state
from .diagram import build_diagram
from .pll_drive import build_pll_drive, pll_scale_factor_V_per_dps, pll_steady_state
from .effects import EffectSet
from .result import SimResult
from .errors import InputError
from .output import format_bytes
from .scenario import Scenario
from .summary import summarize

#: Peak memory per output sample of a run, bytes: measured 420 (envelope engine, 100 Hz) and 750 (carrier
#: engine, 20 kHz) per sample over a short run's baseline, the record and its CSV text included; rounded up.
MEMORY_PER_SAMPLE_B = 1024
#: CSV bytes per cell of a written record (12 significant digits, sign, exponent, comma).
CSV_BYTES_PER_CELL = 13
#: Channels of a simulated record.
RECORD_CHANNELS = 9


def available_memory_bytes() -> int | None:
    """Memory the system can give this process now (``MemAvailable``), or None when unknown.

    Returns
    -------
    int or None
    """
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def record_size(scn: Scenario) -> dict:
    """How large a run of ``scn`` is: output samples, peak memory and CSV size (estimates).

    Parameters
    ----------
    scn : Scenario

    Returns
    -------
    dict
        ``samples``, ``memory_bytes`` and ``csv_bytes``.
    """
    n = int(scn.duration_s * float(scn.settings["scenario"]["output_rate_Hz"])) + 1
    return {"samples": n, "memory_bytes": n * MEMORY_PER_SAMPLE_B,
            "csv_bytes": n * RECORD_CHANNELS * CSV_BYTES_PER_CELL}


def check_fits_in_memory(scn: Scenario) -> None:
    """Refuse, before simulating, a run whose record cannot fit in the memory available.

    Parameters
    ----------
    scn : Scenario

    Raises
    ------
    InputError
        Naming ``scenario.duration_s`` x ``scenario.output_rate_Hz`` and the sizes.
    """
    size = record_size(scn)
    avail = available_memory_bytes()
    if avail is not None and size["memory_bytes"] > avail:
        rate = float(scn.settings["scenario"]["output_rate_Hz"])
        raise InputError(f"scenario.duration_s x scenario.output_rate_Hz = {scn.duration_s:g} s x {rate:g} Hz = "
                         f"{size['samples']:.4g} samples: the run needs about {format_bytes(size['memory_bytes'])} "
                         f"of memory, more than the {format_bytes(avail)} available; shorten the run or lower "
                         "the output rate", scn.path)


def vref_profile_V(scn: Scenario, t_s: np.ndarray, temperature_C: np.ndarray) -> np.ndarray:
    """The AGC set-point (V) at each sample: Vref(T) times the scenario's set-point factor.

    Parameters
    ----------
    scn : Scenario
    t_s, temperature_C : ndarray

    Returns
    -------
    ndarray
    """
    ref = scn.device.values["circuit"]["reference"]
    dT = np.asarray(temperature_C) - scn.device.reference_temperature_C
    return law.linear_tc(ref["vref_V"], dT, ref["vref_tc_per_K"]) * np.asarray(scn.vref_factor(t_s))


def pll_predictions(device, die_C: float, board_C: float) -> dict:
    """The locked PLL drive's steady state, as :func:`predictions` gives the self-oscillating loop's.

    ``loop_phase_error_rad`` is the phase by which the lock point sits off the drive resonance,
    ``atan(2 Q (f - f_d) / f_d)``.

    Parameters
    ----------
    device : Device
    die_C, board_C : float
        Die and board temperatures.

    Returns
    -------
    dict
    """
    pll = build_pll_drive(device, die_C, board_C=board_C)
    ss = pll_steady_state(pll)
    sf = pll_scale_factor_V_per_dps(pll)
    res = pll.dg.resonator
    phase = float(np.arctan(2 * res.q_drive * (ss.f_Hz - res.f_drive_Hz) / res.f_drive_Hz))
    return dict(temperature_C=float(board_C), drive_frequency_Hz=ss.f_Hz, drive_amplitude_m=ss.amplitude_m,
                agc_effort_V=ss.agc_effort_V, scale_factor_V_per_dps=sf, zero_rate_bias_dps=ss.rate_V / sf,
                loop_phase_error_rad=phase, quadrature_V=ss.quadrature_V)


def predictions(scn: Scenario, temperature_C: float) -> dict:
    """Analytic (averaged-model) steady state after a long hold at the sensor temperature ``temperature_C``.

    The board (electronics) is at ``temperature_C``; the die at the same, or off it by the
    ``thermal_lag`` effect's offset.

    Parameters
    ----------
    scn : Scenario
    temperature_C : float
        Case (sensor) temperature.

    Returns
    -------
    dict
    """
    die_C = EffectSet(scn.effects).settled_die_temperature(temperature_C)
    if scn.device.drive_topology == "pll":
        return pll_predictions(scn.device, die_C, temperature_C)
    dg = build_diagram(scn.device, die_C, board_C=temperature_C)
    ss = steady_state(dg)
    sf = scale_factor_V_per_dps(dg)
    return dict(temperature_C=float(temperature_C), drive_frequency_Hz=ss.f_Hz, drive_amplitude_m=ss.amplitude_m,
                agc_effort_V=ss.agc_effort_V, scale_factor_V_per_dps=sf, zero_rate_bias_dps=ss.rate_V / sf,
                loop_phase_error_rad=ss.loop_phase_error_rad, quadrature_V=ss.quadrature_V)


def run_scenario(scn: Scenario, progress: bool | None = None) -> tuple[SimResult, dict]:
    """Simulate ``scn`` and summarise it.

    Parameters
    ----------
    scn : Scenario
    progress : bool, optional
        Progress bar on stderr (default: for runs expected to take more than a few seconds).

    Returns
    -------
    tuple
        (SimResult, summary dict)

    Raises
    ------
    InputError
        When the record cannot fit in the memory available (before simulating).
    """
    check_fits_in_memory(scn)
    if scn.fidelity() == "carrier":
        from .carrier.engine import run_carrier
        res = run_carrier(scn, progress=progress)
    else:
        from .envelope.engine import run_envelope
        res = run_envelope(scn, progress=progress)
    t = res.time_s
    vref = vref_profile_V(scn, t, res["temperature_C"])
    ring_s = scn.device.reference_diagram.resonator.ringdown_time_constant_s("sense")
    summary = summarize(res, vref, scn.device.values["circuit"]["pi"]["u_max_V"],
                        predicted=predictions(scn, float(res["temperature_C"][-1])),
                        transient_s=3 * ring_s, by_temperature_predicted=lambda T: predictions(scn, T))
    return res, summary
