"""Paper 000's phase-shifter drive against a PLL drive: what a designer compares, measured by simulation.

:func:`compare_drives` runs the shipped scenarios with either drive topology (``[circuit.drive]
topology``) on the same device: the start-up (carrier engine), the oven of paper 004 (envelope
engine), rate steps at -40, 25 and 85 C, and a static record at 25 C with noise; it returns the
figures of merit and the traces a figure needs. ``benchmarks/drive_loops.py`` writes them as
docs/drive_loops.md and its figure.
"""

from __future__ import annotations

import numpy as np

from scipy.interpolate import CubicSpline

from ..analysis.allan import allan_deviation
from ..effects import EffectSet
from ..carrier.engine import run_carrier
from ..envelope.engine import run_envelope
from ..pll_drive import build_pll_drive, pll_steady_state
from ..scenario import load_scenario

#: The two drive topologies compared, by their ``circuit.drive.topology`` value.
TOPOLOGIES = ("self-oscillating", "pll")
#: Rate of the steps the scale factor is read from (deg/s).
STEP_DPS = 20.0
NOISE_OFF = ["noise.brownian=false", "noise.electronic=false", "noise.flicker=false", "noise.quantization=false",
             "noise.rate_random_walk=false"]


def _over(topology: str) -> list[str]:
    return [f"circuit.drive.topology={topology}"]


def startup_figures(res, vref_V: float) -> dict:
    """Time to 90 % amplitude, and the time after which amplitude (1 %) and frequency (0.1 Hz) stay settled.

    The frequency is read as its 10 ms moving mean: a zero-crossing counter's reading of a noisy pickoff
    scatters by about 0.07 Hz per half-millisecond sample.

    Parameters
    ----------
    res : SimResult
        A start-up record.
    vref_V : float
        The amplitude set-point.

    Returns
    -------
    dict
        ``t90_s``, ``settled_s``.
    """
    t, a, f = res.time_s, res["drive_amplitude_V"], np.asarray(res["drive_frequency_Hz"])
    k = max(1, int(round(0.01 / (t[1] - t[0]))))
    t90 = float(t[np.flatnonzero(a >= 0.9 * vref_V)[0]])
    f = np.convolve(np.where(np.isfinite(f), f, np.nanmean(f)), np.ones(k) / k, mode="valid")  # ends at t[k-1:]
    t, a = t[k - 1:], a[k - 1:]
    f_end = np.mean(f[-max(10, len(f) // 20):])
    bad = (np.abs(a / vref_V - 1) > 0.01) | ~(np.abs(f - f_end) <= 0.1)
    return {"t90_s": t90, "settled_s": float(t[np.flatnonzero(bad)[-1] + 1]) if bad.any() else 0.0}


def hold_means(res, min_hold_s: float = 600.0, values=None) -> tuple[np.ndarray, np.ndarray]:
    """Mean temperature and zero-rate output (deg/h) over the second half of each temperature hold.

    Parameters
    ----------
    res : SimResult
    min_hold_s : float, optional
        Shortest hold taken.
    values : ndarray, optional
        Another per-sample quantity to average instead of the zero-rate output (taken as is).

    Returns
    -------
    tuple of ndarray
        Temperatures (degC) and biases (deg/h), or the means of ``values``.
    """
    t, T = res.time_s, np.asarray(res["temperature_C"])
    r = np.asarray(res["rate_dps"]) if values is None else np.asarray(values) / 3600.0
    edges = np.flatnonzero(np.diff(T) != 0) + 1
    Ts, bs = [], []
    for a, b in zip(np.r_[0, edges], np.r_[edges, len(T)]):
        if t[b - 1] - t[a] >= min_hold_s:
            m = (a + b) // 2
            Ts.append(float(T[m:b].mean()))
            bs.append(3600.0 * float(r[m:b].mean()))
    return np.array(Ts), np.array(bs)


def compare_drives(quick: bool = False, log=print) -> dict:
    """Both drive topologies on ``fmvmg_a``: start-up, oven, scale factor over temperature, noise.

    Parameters
    ----------
    quick : bool, optional
        Shortened runs (checks the machinery; the figures are not the page's).
    log : callable, optional
        Progress lines.

    Returns
    -------
    dict
        Per topology: ``figures`` (the table's numbers) and ``traces`` (for the figure).
    """
    out = {}
    oven_s = 6000.0 if quick else None  # quick: the 25 C hold and part of the 60 C one
    static_s = 600.0 if quick else 7200.0
    for topo in TOPOLOGIES:
        fig, tr = {}, {}
        name = "pll_startup" if topo == "pll" else "startup"
        log(f"{topo}: start-up ({name}, carrier engine)")
        scn = load_scenario(name, ["scenario.duration_s=0.6"] + _over(topo))
        res = run_carrier(scn, progress=False)
        fig.update(startup_figures(res, scn.device.reference_diagram.vref_V))
        fig["startup_offset_Hz"] = 20.0 if topo == "pll" else 0.0
        tr["startup"] = (res.time_s, np.asarray(res["drive_amplitude_V"]))
        log(f"{topo}: oven_004 (envelope engine)")
        ov = _over(topo) + ([f"scenario.duration_s={oven_s}"] if oven_s else [])
        scn = load_scenario("oven_004", ov)
        res = run_envelope(scn, progress=not quick)
        keep = res.time_s > 10.0
        dev = scn.device
        # the die temperature at each sample's middle: the frequency channel is a mean over the sample
        t_mid = res.time_s - 0.5 / scn.settings["scenario"]["output_rate_Hz"]
        fx = EffectSet(scn.effects)
        T_die = np.asarray(fx.die_temperature(t_mid, np.asarray(scn.temperature(t_mid), dtype=float)))
        grid = np.linspace(T_die.min() - 1, T_die.max() + 1, 64)
        f_res = CubicSpline(grid, [dev.at(T)["mechanics"]["f_drive_Hz"] for T in grid])(T_die)
        df_all = np.asarray(res["drive_frequency_Hz"]) - f_res
        df = df_all[keep]
        amp = np.asarray(res.internal["drive_displacement_amplitude_m"])[keep]
        fig["oven_amplitude_range_rel"] = float(np.ptp(amp) / np.mean(amp))
        _, df_holds = hold_means(res, values=df_all)
        fig["hold_freq_off_resonance_range_Hz"] = float(np.ptp(df_holds))
        fig["hold_freq_off_resonance_max_Hz"] = float(np.max(np.abs(df_holds)))
        if topo == "pll":  # the oscillator's lag behind its steady lock point while the oven ramps
            lock = CubicSpline(grid, [pll_steady_state(build_pll_drive(dev, T)).f_Hz for T in grid])(T_die)
            fig["ramp_tracking_error_max_Hz"] = float(np.max(np.abs(np.asarray(res["drive_frequency_Hz"]) - lock)[keep]))
        Ts, bs = hold_means(res)
        slope, icpt = np.polyfit(Ts, bs, 1)
        fig["bias_tc_dph_per_K"] = float(slope)
        fig["bias_range_dph"] = float(np.ptp(bs))
        fig["bias_residual_after_line_dph"] = float(np.max(np.abs(bs - (slope * Ts + icpt))))
        every = max(1, int(keep.sum()) // 20000)  # the figure needs no more points than that
        tr["oven"] = (res.time_s[keep][::every], df[::every], np.asarray(res["temperature_C"])[keep][::every])
        tr["holds"] = (Ts, bs)
        log(f"{topo}: rate steps at -40, 25, 85 C (envelope engine)")
        sfs = []
        for T in (-40.0, 25.0, 85.0):
            scn = load_scenario("rate_steps", NOISE_OFF + _over(topo) + [
                "scenario.duration_s=1.2", "scenario.output_rate_Hz=1000", "initial.state=steady",
                f"temperature.start_C={T}", "temperature.segments=[]",
                f"rate.segments=[{{hold_s=0.6}}, {{step_to_dps={STEP_DPS}}}]"], fidelity="envelope")
            r = run_envelope(scn, progress=False)
            t, y = r.time_s, np.asarray(r["rate_V"])
            sfs.append((y[(t > 1.0)].mean() - y[(t > 0.4) & (t < 0.6)].mean()) / STEP_DPS)
        sfs = np.array(sfs)
        fig["sf_V_per_dps_25C"] = float(sfs[1])
        fig["sf_tc_ppm_per_K"] = float(1e6 * np.polyfit([-40.0, 25.0, 85.0], sfs / sfs[1], 1)[0])
        log(f"{topo}: static_25C, {static_s:g} s with noise (envelope engine)")
        scn = load_scenario("static_25C", _over(topo) + [f"scenario.duration_s={static_s}",
                                                         "scenario.output_rate_Hz=100"])
        r = run_envelope(scn, progress=not quick)
        al = allan_deviation(np.asarray(r["rate_dps"]), 100.0)
        fig["arw_deg_per_sqrt_h"] = float(al.arw_deg_per_sqrt_h)
        fig["bias_instability_deg_per_h"] = float(al.bias_instability_deg_per_h)
        tr["allan"] = (al.taus_s, 3600.0 * al.adev)
        out[topo] = {"figures": fig, "traces": tr}
    return out


__all__ = ["compare_drives", "startup_figures", "hold_means", "TOPOLOGIES"]
