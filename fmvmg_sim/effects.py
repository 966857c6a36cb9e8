"""Unmodelled effects (docs/formats.md section 4), switched on in a scenario's ``[effects]`` table.

Each effect is a small model with 1-3 physical parameters, bounds and a prior range
(physics brief section 4), acting where the physics acts:

* through the device's temperature laws (in both engines and in the averaged model), at the
  die temperature for the MEMS (``quadrature_drift``, ``q_factor_drift``, ``mode_split_drift``,
  ``duffing``) and at the board temperature for the electronics (``feedthrough``,
  ``reference_drift``, ``demod_phase_drift``);
* through the die temperature itself: ``thermal_lag`` (the MEMS, drive frequency included,
  follow the lagged die temperature; the board and its electronics stay with the case, which
  the sensor reads);
* through time-history signals: ``thermal_hysteresis`` and ``stress_relaxation`` change the
  quadrature stiffness (so quadrature and, through the phase errors, bias move together);
  ``temperature_rate`` adds an equivalent rate proportional to dT_die/dt;
* through noise and acquisition: ``flicker_noise`` (extra 1/f on the demodulation phase and
  the output), ``quantization`` (a coarser DAQ).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from .errors import InputError


@dataclass(frozen=True)
class Param:
    """One effect parameter: physical bounds (hard) and a prior range (typical magnitudes).

    Parameters
    ----------
    unit : str
    lo, hi : float
        Physical bounds.
    prior : tuple of float
        Typical magnitude range (the case generator draws from it, with a random sign when
        ``signed``).
    signed : bool
        Whether either sign is plausible.
    """

    unit: str
    lo: float
    hi: float
    prior: tuple
    signed: bool = False


#: Effect models: name -> {parameter: Param}.
MODELS: dict[str, dict[str, Param]] = {
    "thermal_lag": {"tau_s": Param("s", 10.0, 7200.0, (300.0, 900.0)),
                    "offset_K": Param("K", -5.0, 5.0, (0.2, 1.0))},
    "thermal_hysteresis": {"quad_rel": Param("1", -0.2, 0.2, (0.003, 0.02), signed=True),
                           "width_K": Param("K", 0.5, 100.0, (5.0, 20.0))},
    "temperature_rate": {"g_dph_per_K_per_min": Param("deg/h per K/min", -2000.0, 2000.0, (20.0, 100.0), signed=True)},
    "demod_phase_drift": {"kappa_urad_per_K": Param("urad/K", -5000.0, 5000.0, (20.0, 200.0), signed=True)},
    "quadrature_drift": {"beta_per_K": Param("1/K", -0.05, 0.05, (5e-4, 5e-3), signed=True)},
    "q_factor_drift": {"q_tc_per_K": Param("1/K", -0.05, 0.05, (2e-3, 1e-2), signed=True)},
    "mode_split_drift": {"split_Hz_per_K": Param("Hz/K", -2.0, 2.0, (0.01, 0.06), signed=True)},
    "feedthrough": {"c_ft_fF": Param("fF", 0.0, 100.0, (1.0, 10.0)),
                    "tc_per_K": Param("1/K", -0.01, 0.01, (1e-4, 5e-4))},
    "duffing": {"k3_rel": Param("1", -0.01, 0.01, (1e-4, 1e-3), signed=True)},
    "flicker_noise": {"h_phase_rad2": Param("rad^2", 0.0, 1e-6, (5e-10, 5e-9)),
                      "h_output_dps2": Param("(deg/s)^2", 0.0, 1e-2, (1e-5, 1e-4))},
    "reference_drift": {"vref_tc_per_K": Param("1/K", -0.01, 0.01, (1e-5, 1e-4), signed=True),
                        "rectifier_mV_per_K": Param("mV/K", -10.0, 10.0, (0.2, 2.0), signed=True)},
    "stress_relaxation": {"quad_rel": Param("1", -0.2, 0.2, (0.003, 0.02), signed=True),
                          "tau_h": Param("h", 0.01, 1000.0, (1.0, 24.0))},
    "quantization": {"lsb_V": Param("V", 0.0, 1.0, (1e-3, 1e-2))},
}

#: The effect names of docs/formats.md section 4.
EFFECT_NAMES = tuple(MODELS)


def validate_effects(table: dict, where: str) -> dict:
    """Check an ``[effects]`` table: known names, known parameters, values inside the physical bounds.

    Parameters
    ----------
    table : dict
        ``{effect: {param: value}}``; missing parameters take the middle of their prior range.
    where : str
        Key path for messages.

    Returns
    -------
    dict
        Complete, validated parameters per effect.

    Raises
    ------
    InputError
    """
    from .tomlio import suggest
    if not isinstance(table, dict):
        raise InputError("expected a table of effects", where)
    out = {}
    for name, params in table.items():
        if name not in MODELS:
            raise InputError(f"unknown effect{suggest(name, EFFECT_NAMES)}; known: {list(EFFECT_NAMES)}",
                             f"{where}.{name}")
        if not isinstance(params, dict):
            raise InputError("expected a table of parameters, e.g. { tau_s = 600 }", f"{where}.{name}")
        spec = MODELS[name]
        full = {}
        for pname, ps in spec.items():
            v = params.get(pname, 0.5 * (ps.prior[0] + ps.prior[1]))
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise InputError(f"expected a number in {ps.unit}, got {v!r}", f"{where}.{name}.{pname}")
            if not ps.lo <= v <= ps.hi:
                raise InputError(f"{v!r} {ps.unit} is outside the physical bounds [{ps.lo}, {ps.hi}]",
                                 f"{where}.{name}.{pname}")
            full[pname] = float(v)
        unknown = set(params) - set(spec)
        if unknown:
            raise InputError(f"unknown parameter(s) {sorted(unknown)}; expected {list(spec)}", f"{where}.{name}")
        out[name] = full
    return out


class EffectSet:
    """The effects of a scenario, applied to a device and to a run's time base.

    Parameters
    ----------
    effects : dict
        Validated ``{effect: {param: value}}``.
    """

    def __init__(self, effects: dict | None = None):
        self.effects = dict(effects or {})

    def __bool__(self) -> bool:
        return bool(self.effects)

    def get(self, name: str) -> dict | None:
        """Parameters of ``name`` if switched on.

        Parameters
        ----------
        name : str

        Returns
        -------
        dict or None
        """
        return self.effects.get(name)

    def apply_to_device(self, device):
        """The device with the temperature-law effects folded into its values.

        Parameters
        ----------
        device : fmvmg_sim.device.Device

        Returns
        -------
        fmvmg_sim.device.Device
        """
        from .device import Device
        v = copy.deepcopy(device.values)
        th, ci, me = v["thermal"], v["circuit"], v["mechanics"]
        if (e := self.get("quadrature_drift")):
            th["quadrature_tc_per_K"] += e["beta_per_K"]
        if (e := self.get("q_factor_drift")):
            th["q_extra_tc_per_K"] = th.get("q_extra_tc_per_K", 0.0) + e["q_tc_per_K"]
        if (e := self.get("mode_split_drift")):
            th["split_extra_Hz_per_K"] = th.get("split_extra_Hz_per_K", 0.0) + e["split_Hz_per_K"]
        if (e := self.get("feedthrough")):
            ci["sense_pickoff"]["c_feedthrough_F"] += e["c_ft_fF"] * 1e-15
            ci["sense_pickoff"]["c_feedthrough_tc_per_K"] = e["tc_per_K"]
        if (e := self.get("duffing")):
            me["duffing_k3_rel"] = e["k3_rel"]
        if (e := self.get("reference_drift")):
            ci["reference"]["vref_tc_per_K"] += e["vref_tc_per_K"]
            ci["rectifier"]["offset_tc_V_per_K"] += e["rectifier_mV_per_K"] * 1e-3
        if (e := self.get("demod_phase_drift")):
            ci["demodulator"]["phase_tc_rad_per_K"] = ci["demodulator"].get("phase_tc_rad_per_K", 0.0) \
                + e["kappa_urad_per_K"] * 1e-6
        if (e := self.get("flicker_noise")):
            v["noise"]["flicker_phase_rad2"] += e["h_phase_rad2"]
            v["noise"]["flicker_output_dps2"] += e["h_output_dps2"]
        if (e := self.get("quantization")):
            v["noise"]["quantization_lsb_V"] = max(v["noise"]["quantization_lsb_V"], e["lsb_V"])
        return Device(v, device.path)

    def die_temperature(self, t_s: np.ndarray, case_C: np.ndarray) -> np.ndarray:
        """Die temperature: the case temperature through the thermal lag (and its offset).

        Exact first-order lag for a case temperature linear between samples.

        Parameters
        ----------
        t_s : ndarray
            Increasing times.
        case_C : ndarray
            Case (sensor) temperature at those times.

        Returns
        -------
        ndarray
        """
        e = self.get("thermal_lag")
        case_C = np.asarray(case_C, dtype=float)
        if not e:
            return case_C.copy()
        return first_order_lag(t_s, case_C, e["tau_s"]) + e["offset_K"]

    def settled_die_temperature(self, case_C: float) -> float:
        """Die temperature after a long hold at the case temperature ``case_C`` (the lag's offset only).

        Parameters
        ----------
        case_C : float

        Returns
        -------
        float
        """
        e = self.get("thermal_lag")
        return float(case_C) + (e["offset_K"] if e else 0.0)

    def board_temperature(self, t_s: np.ndarray, case_C: np.ndarray) -> np.ndarray:
        """Board (electronics) temperature: the case temperature, which the sensor reads.

        Parameters
        ----------
        t_s : ndarray
            Times (unused: the board has no lag of its own).
        case_C : ndarray
            Case (sensor) temperature at those times.

        Returns
        -------
        ndarray
        """
        return np.asarray(case_C, dtype=float).copy()

    def signals(self, t_s: np.ndarray, die_C: np.ndarray) -> dict:
        """Time-history signals: extra rate (deg/s) and relative quadrature-stiffness change.

        Parameters
        ----------
        t_s, die_C : ndarray

        Returns
        -------
        dict
            ``rate_dps`` and ``quad_rel`` arrays.
        """
        n = len(t_s)
        rate = np.zeros(n)
        quad = np.zeros(n)
        if (e := self.get("temperature_rate")):
            dTdt_K_per_min = np.gradient(die_C, t_s) * 60.0 if n > 1 else np.zeros(n)
            rate += e["g_dph_per_K_per_min"] / 3600.0 * dTdt_K_per_min
        if (e := self.get("thermal_hysteresis")):
            quad += e["quad_rel"] * hysteresis_state(die_C, e["width_K"])
        if (e := self.get("stress_relaxation")):
            quad += e["quad_rel"] * (1.0 - np.exp(-np.asarray(t_s) / (3600.0 * e["tau_h"])))
        return {"rate_dps": rate, "quad_rel": quad}


def first_order_lag(t_s: np.ndarray, u: np.ndarray, tau_s: float) -> np.ndarray:
    """Output of ``tau y' = u - y`` from ``y(t0) = u(t0)``, exact for ``u`` linear between samples.

    Parameters
    ----------
    t_s, u : ndarray
    tau_s : float

    Returns
    -------
    ndarray
    """
    t = np.asarray(t_s, dtype=float)
    u = np.asarray(u, dtype=float)
    y = np.empty_like(u)
    if len(u) == 0:
        return y
    y[0] = u[0]
    dt = np.diff(t)
    a = np.exp(-dt / tau_s)
    # FOH: y+ = a y + (1 - a) u0 + (u1 - u0) (1 - tau (1 - a)/dt)
    b = 1.0 - tau_s * (1.0 - a) / dt
    du = np.diff(u)
    from scipy.signal import lfilter
    if np.allclose(dt, dt[0]) if len(dt) else True:
        drive = (1.0 - a) * u[:-1] + du * b
        zi = np.array([a[0] * y[0]]) if len(dt) else None
        if len(dt):
            y[1:] = lfilter([1.0], [1.0, -a[0]], drive, zi=zi)[0]
        return y
    for k in range(len(dt)):
        y[k + 1] = a[k] * y[k] + (1.0 - a[k]) * u[k] + du[k] * b[k]
    return y


def hysteresis_state(T: np.ndarray, width_K: float) -> np.ndarray:
    """Duhem-type hysteresis state in [-1, 1]: heating drives it to +1, cooling to -1, over ``width_K``.

    ``dH = (sign(dT) - H) |dT| / width``; it depends only on the temperature path (not its
    speed) and persists through holds, unlike a thermal lag.

    Parameters
    ----------
    T : ndarray
        Temperature path.
    width_K : float

    Returns
    -------
    ndarray
    """
    T = np.asarray(T, dtype=float)
    H = np.zeros_like(T)
    dT = np.diff(T)
    decay = np.exp(-np.abs(dT) / width_K)
    target = np.sign(dT)
    h = 0.0
    for k in range(len(dT)):
        if dT[k] != 0.0:
            h = target[k] + (h - target[k]) * decay[k]
        H[k + 1] = h
    return H
