"""Synthetic gyro records with a known true rate (compensation.md section 5).

The rate output is

    y = (1 + S dT) w_true + b0 + a1 dT + a2 dT^2 + c dT/dt + white(N) + flicker(B) + RRW(K)

with dT = T - T_ref. It stands in for the simulator's oven runs while developing and
testing the compensators; every component is returned separately so tests and the
threshold calibration can label what each IMF holds. Deterministic for a given seed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..record import Record

PROFILES = ("heating", "cooling", "ramp", "soak", "cycle")
RATES = ("static", "sines", "steps", "mixed")


@dataclass(frozen=True)
class DriftParams:
    """Error-model coefficients (compensation.md section 5 defaults).

    Parameters
    ----------
    arw_dph_per_rtHz : float
        White rate noise density N in deg/h/sqrt(Hz).
    bias_instability_dph : float
        Flicker level B in deg/h (ADEV floor 0.664 B).
    rrw_dph_per_rts : float
        Rate random walk K in deg/h/sqrt(s).
    b0_dph, a1_dph_per_C, a2_dph_per_C2, c_dph_per_C_per_min : float
        Bias and its temperature, temperature-squared and temperature-rate coefficients.
    scale_ppm_per_C : float
        Scale-factor temperature coefficient S in ppm/degC.
    T_ref_C : float
        Reference temperature of dT.
    temp_noise_C : float
        White noise of the temperature sensor in degC (per sample).
    """

    arw_dph_per_rtHz: float = 100.0
    bias_instability_dph: float = 30.0
    rrw_dph_per_rts: float = 0.5
    b0_dph: float = 50.0
    a1_dph_per_C: float = 2.0
    a2_dph_per_C2: float = 0.02
    c_dph_per_C_per_min: float = 25.0
    scale_ppm_per_C: float = 100.0
    T_ref_C: float = 25.0
    temp_noise_C: float = 0.005


def temperature_profile(t_s: np.ndarray, profile: str = "heating", T_low_C: float = 25.0,
                        T_high_C: float = 55.0, tau_s: float = 900.0,
                        ramp_C_per_min: float = 1.0) -> np.ndarray:
    """Chamber-driven die temperature in degC.

    Parameters
    ----------
    t_s : ndarray
        Time base in s.
    profile : {"heating", "cooling", "ramp", "soak", "cycle"}
        Heating/cooling: first-order step (time constant ``tau_s``) after a 10 % soak;
        ramp: triangle between the limits at ``ramp_C_per_min``; soak: constant at
        ``T_low_C``; cycle: heating then cooling, each over half the record.
    T_low_C, T_high_C, tau_s, ramp_C_per_min : float
        Limits, first-order time constant and ramp rate.

    Returns
    -------
    ndarray
        Temperature in degC.
    """
    t = np.asarray(t_s, float) - t_s[0]
    span = max(t[-1], 1e-9)
    step = lambda t0: 1.0 - np.exp(-np.clip(t - t0, 0.0, None) / tau_s)  # noqa: E731
    dT = T_high_C - T_low_C
    if profile == "heating":
        return T_low_C + dT * step(0.1 * span)
    if profile == "cooling":
        return T_high_C - dT * step(0.1 * span)
    if profile == "soak":
        return np.full_like(t, T_low_C)
    if profile == "ramp":
        period_s = 2.0 * abs(dT) / (ramp_C_per_min / 60.0)
        phase = (t / period_s) % 1.0
        return T_low_C + dT * (1.0 - np.abs(2.0 * phase - 1.0))
    if profile == "cycle":
        up = step(0.05 * span)
        down = step(0.55 * span)
        return T_low_C + dT * (up - down * up[np.searchsorted(t, 0.55 * span)])
    raise ValueError(f"unknown profile {profile!r}; expected one of {PROFILES}")


def true_rate(t_s: np.ndarray, kind: str = "static") -> np.ndarray:
    """Applied angular rate in deg/s.

    Parameters
    ----------
    t_s : ndarray
        Time base in s.
    kind : {"static", "sines", "steps", "mixed"}
        Zero; 0.5 deg/s at 0.2 Hz + 0.2 deg/s at 2 Hz + 0.1 deg/s at 15 Hz; +-5 deg/s steps
        lasting 60 s every 600 s; or static first third, sines second, steps last third.

    Returns
    -------
    ndarray
        Rate in deg/s.
    """
    t = np.asarray(t_s, float) - t_s[0]
    sines = (0.5 * np.sin(2 * np.pi * 0.2 * t) + 0.2 * np.sin(2 * np.pi * 2.0 * t)
             + 0.1 * np.sin(2 * np.pi * 15.0 * t))
    k = np.floor(t / 600.0)
    steps = np.where((t % 600.0) < 60.0, 5.0 * np.where(k % 2 == 0, 1.0, -1.0), 0.0)
    if kind == "static":
        return np.zeros_like(t)
    if kind == "sines":
        return sines
    if kind == "steps":
        return steps
    if kind == "mixed":
        third = t[-1] / 3.0
        return np.where(t < third, 0.0, np.where(t < 2 * third, sines, steps))
    raise ValueError(f"unknown rate kind {kind!r}; expected one of {RATES}")


def flicker_noise(n: int, fs_Hz: float, bias_instability: float, rng: np.random.Generator) -> np.ndarray:
    """1/f noise with two-sided PSD B^2/(2 pi f) (IEEE 952), so that its ADEV floor is 0.664 B.

    Parameters
    ----------
    n : int
        Number of samples.
    fs_Hz : float
        Sampling rate.
    bias_instability : float
        B, in the unit of the returned noise.
    rng : numpy.random.Generator
        Random source.

    Returns
    -------
    ndarray
        Flicker noise (zero mean).
    """
    w = rng.standard_normal(n)  # one-sided PSD 2/fs
    spec = np.fft.rfft(w)
    f = np.fft.rfftfreq(n, 1.0 / fs_Hz)
    gain = np.zeros_like(f)
    gain[1:] = np.sqrt(bias_instability**2 / (np.pi * f[1:]) * fs_Hz / 2.0)  # one-sided B^2/(pi f)
    return np.fft.irfft(spec * gain, n)


def make_record(duration_s: float = 3600.0, fs_Hz: float = 100.0, profile: str = "heating",
                rate: str = "static", seed: int = 0, params: DriftParams = DriftParams(),
                return_components: bool = False, **profile_kw):
    """A synthetic record (``time_s``, ``temperature_C``, ``rate_dps``, ``rate_true_dps``).

    Parameters
    ----------
    duration_s, fs_Hz : float
        Length and sampling rate.
    profile : str
        Temperature profile, see :func:`temperature_profile`.
    rate : str
        True-rate kind, see :func:`true_rate`.
    seed : int
        Seed of every random component.
    params : DriftParams
        Error-model coefficients.
    return_components : bool
        Also return the components of ``rate_dps`` (deg/s) by name: ``true``, ``scale``,
        ``thermal``, ``white``, ``flicker``, ``rrw`` (they sum to ``rate_dps``).
    **profile_kw
        Passed to :func:`temperature_profile`.

    Returns
    -------
    Record or (Record, dict of str to ndarray)
    """
    n = int(round(duration_s * fs_Hz))
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs_Hz
    p = params
    T = temperature_profile(t, profile, **profile_kw)
    dT = T - p.T_ref_C
    dTdt_C_per_min = np.gradient(T, t) * 60.0
    w = true_rate(t, rate)
    h = 1.0 / 3600.0  # deg/h -> deg/s
    comp = {
        "true": w,
        "scale": p.scale_ppm_per_C * 1e-6 * dT * w,
        "thermal": h * (p.b0_dph + p.a1_dph_per_C * dT + p.a2_dph_per_C2 * dT**2
                        + p.c_dph_per_C_per_min * dTdt_C_per_min),
        "white": h * p.arw_dph_per_rtHz * np.sqrt(fs_Hz) * rng.standard_normal(n),
        "flicker": h * flicker_noise(n, fs_Hz, p.bias_instability_dph, rng),
        "rrw": h * p.rrw_dph_per_rts * np.cumsum(rng.standard_normal(n)) / np.sqrt(fs_Hz),
    }
    y = sum(comp.values())
    T_meas = T + p.temp_noise_C * rng.standard_normal(n)
    meta = {"source": "synthetic", "generator": "fmvmg_sim.compensation.synthetic", "profile": profile,
            "rate": rate, "seed": str(seed), **{k: str(v) for k, v in asdict(p).items()}}
    rec = Record({"time_s": t, "temperature_C": T_meas, "rate_dps": y, "rate_true_dps": w}, meta)
    return (rec, comp) if return_components else rec
