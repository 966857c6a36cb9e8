"""Scenarios as TOML, validated: what to simulate, for how long, under which temperature and rate.

::

    [scenario]
    name = "startup"
    device_file = "devices/fmvmg_a.toml"   # relative to this file, or a name in scenarios/devices/
    duration_s = 0.3
    output_rate_Hz = 2000.0
    seed = 1
    fidelity = "carrier"                  # carrier | envelope | auto (envelope above 60 s)
    steps_per_cycle = 32                  # carrier engine
    envelope_step_s = 0.01                # envelope engine: longest step (exact discretisation)

    [initial]   drive_displacement_m = 10e-9, state = "rest" | "steady"
    [temperature]  start_C + segments (hold_s, ramp_to_C + rate_C_per_min | duration_s, step_to_C) or points
    [rate]         start_dps + segments (as above with _dps, plus sines) or points
    [vref]         start_factor + segments (step_to_factor, ...): the AGC set-point as a multiple of Vref
    [noise]        brownian, electronic, flicker, quantization, rate_random_walk = true/false
    [circuit.*]    overrides of the device file's circuit (e.g. circuit.pi.kp = 100)
    [device.*]     overrides of any device-file value (e.g. device.mechanics.q_drive = 1e5)
    [effects]      unmodelled effects switched on (see fmvmg_sim.effects)

``--set KEY=VALUE`` overrides any of these before validation.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .device import Device, load_device
from .effects import EffectSet, validate_effects
from .errors import InputError
from .paths import devices_dir, resolve_device, resolve_scenario, shipped_devices, shipped_scenarios
from .profiles import PiecewiseProfile, build_profile
from .schema import Bool, Choice, Num, Text, validate_tree
from .tomlio import load_toml, parse_override, set_path, suggest

SCENARIO_SCHEMA = {
    "scenario": {
        "name": Text(), "description": Text(), "device_file": Text(),
        "duration_s": Num(positive=True), "output_rate_Hz": Num(positive=True),
        "seed": Num(lo=0, integer=True), "fidelity": Choice(("carrier", "envelope", "auto")),
        "steps_per_cycle": Num(lo=8, hi=4096, integer=True),
        "envelope_step_s": Num(positive=True, hi=0.1),
    },
    "initial": {"drive_displacement_m": Num(lo=0, hi=1e-4), "state": Choice(("rest", "steady"))},
    "noise": {k: Bool() for k in ("brownian", "electronic", "flicker", "quantization", "rate_random_walk")},
}
TOP_KEYS = ("scenario", "initial", "temperature", "rate", "vref", "noise", "circuit", "device", "effects")

DEFAULTS = {
    "scenario": {"name": "unnamed", "description": "", "device_file": "fmvmg_a", "output_rate_Hz": 1000.0,
                 "seed": 0, "fidelity": "auto", "steps_per_cycle": 32, "envelope_step_s": 0.01},
    "initial": {"drive_displacement_m": 10e-9, "state": "rest"},
    "noise": {"brownian": True, "electronic": True, "flicker": True, "quantization": True,
              "rate_random_walk": True},
}

#: Above this duration 'auto' fidelity picks the envelope engine.
AUTO_ENVELOPE_ABOVE_S = 60.0


@dataclass
class Scenario:
    """A validated scenario.

    Attributes
    ----------
    path : str
        Source file.
    settings : dict
        ``scenario``, ``initial`` and ``noise`` tables with defaults filled in.
    device : Device
        The device with the scenario's overrides applied.
    temperature : PiecewiseProfile
        Temperature (degC) against time.
    rate : PiecewiseProfile
        Applied rate (deg/s) against time.
    vref_factor : PiecewiseProfile
        Multiplier of the amplitude set-point Vref against time (1 = nominal).
    effects : dict
        The ``[effects]`` table (validated by :mod:`fmvmg_sim.effects`); ``device`` already has
        the temperature-law effects folded in.
    device_nominal : Device
        The device without the effects (its scale factor converts rate_V to rate_dps).
    """

    path: str
    settings: dict
    device: Device
    temperature: PiecewiseProfile
    rate: PiecewiseProfile
    vref_factor: PiecewiseProfile
    effects: dict = field(default_factory=dict)
    device_nominal: Device | None = None

    def __post_init__(self) -> None:
        if self.device_nominal is None:
            self.device_nominal = self.device

    @property
    def name(self) -> str:
        """Scenario name."""
        return self.settings["scenario"]["name"]

    @property
    def duration_s(self) -> float:
        """Simulated duration."""
        return float(self.settings["scenario"]["duration_s"])

    @property
    def seed(self) -> int:
        """Random seed."""
        return int(self.settings["scenario"]["seed"])

    @property
    def noise(self) -> dict:
        """Noise switches."""
        return self.settings["noise"]

    def replace(self, *, scenario: dict | None = None, initial: dict | None = None, noise: dict | None = None,
                device: Device | None = None, device_nominal: Device | None = None,
                temperature: PiecewiseProfile | None = None, rate: PiecewiseProfile | None = None,
                vref_factor: PiecewiseProfile | None = None, effects: dict | None = None) -> "Scenario":
        """A copy with some parts changed, validated as a loaded scenario is; this one is left as it is.

        ``scn.replace(scenario={"duration_s": 600.0, "seed": 3}, initial={"state": "steady"})`` is
        the scenario ``--set scenario.duration_s=600 --set scenario.seed=3 --set initial.state=steady``
        would load.

        Parameters
        ----------
        scenario, initial, noise : dict, optional
            Keys of the ``[scenario]``, ``[initial]`` and ``[noise]`` tables to change (the others kept).
        device : Device, optional
            The device to simulate, used as given (effects already folded in).
        device_nominal : Device, optional
            The device without the effects (its scale factor converts rate_V to rate_dps). Without
            ``device``, the simulated device is this one with the effects folded in.
        temperature, rate, vref_factor : PiecewiseProfile, optional
            Profiles against time: from t = 0, times non-decreasing, values finite.
        effects : dict, optional
            An ``[effects]`` table. Without ``device``, it is folded into the nominal device.

        Returns
        -------
        Scenario
            A new scenario; its device and profiles are shared with this one where unchanged.

        Raises
        ------
        InputError
            An unknown key, a value out of range, a profile out of order or an object of the wrong
            type; the message names it.
        """
        name = self.name
        settings = copy.deepcopy(self.settings)
        for table, changes in (("scenario", scenario), ("initial", initial), ("noise", noise)):
            if changes:
                checked = validate_tree({table: dict(changes)}, SCENARIO_SCHEMA, name)
                settings[table].update(checked[table])
        for label, dev in (("device", device), ("device_nominal", device_nominal)):
            if dev is not None and not isinstance(dev, Device):
                raise InputError(f"expected a Device, got {type(dev).__name__}", f"{name}: {label}")
        profiles = {}
        for label, profile in (("temperature", temperature), ("rate", rate), ("vref_factor", vref_factor)):
            current = getattr(self, label)
            profiles[label] = current if profile is None else _checked_profile(profile, f"{name}: {label}")
        nominal = self.device_nominal if device_nominal is None else device_nominal
        fx = self.effects if effects is None else validate_effects(effects, f"{name}: effects")
        if device is None:
            device = self.device
            if effects is not None or device_nominal is not None:
                device = EffectSet(fx).apply_to_device(nominal) if fx else nominal
        return Scenario(self.path, settings, device, profiles["temperature"], profiles["rate"],
                        profiles["vref_factor"], fx, nominal)

    def fidelity(self) -> str:
        """The engine to use: 'carrier' or 'envelope' ('auto' resolved by duration).

        Returns
        -------
        str
        """
        f = self.settings["scenario"]["fidelity"]
        if f == "auto":
            return "envelope" if self.duration_s > AUTO_ENVELOPE_ABOVE_S else "carrier"
        return f


def load_scenario(path: str | Path, overrides: list[str] | None = None,
                  seed: int | None = None, fidelity: str | None = None) -> Scenario:
    """Load, override and validate a scenario file.

    Parameters
    ----------
    path : str or Path
    overrides : list of str, optional
        ``KEY=VALUE`` strings (``--set``), applied before validation.
    seed : int, optional
        Overrides ``scenario.seed``.
    fidelity : str, optional
        Overrides ``scenario.fidelity``.

    Returns
    -------
    Scenario

    Raises
    ------
    InputError
        Any unknown key, wrong type or unit, bad value, missing device file, or a
        profile whose times do not increase; the message names the key path.
    """
    path = resolve_scenario(path)
    name = str(path)
    if path.is_dir():
        raise InputError("is a folder; expected a scenario TOML file", name)
    if not path.is_file():
        raise InputError(f"file not found (shipped scenarios: {', '.join(shipped_scenarios())})", name)
    tree = load_toml(path)
    set_keys = []
    for text in overrides or []:
        key, value = parse_override(text)
        top = key.split(".")[0]
        if top not in TOP_KEYS:
            raise InputError(f"unknown table {top!r}{suggest(top, TOP_KEYS)}; tables are {list(TOP_KEYS)}",
                             f"--set {key}")
        set_path(tree, key, value)
        set_keys.append((key, text))
    try:
        return _build(tree, path, name, seed, fidelity)
    except InputError as exc:
        raise _blame_override(exc, name, set_keys) from None


def _blame_override(exc: InputError, name: str, set_keys: list[tuple[str, str]]) -> InputError:
    """The error re-addressed to the ``--set`` argument whose value it is about (else unchanged)."""
    where = exc.where or ""
    if not where.startswith(f"{name}: "):
        return exc
    keypath = where[len(name) + 2:]
    for key, text in reversed(set_keys):  # the last --set of a key is the one in effect
        for prefix in ("", "device."):  # [circuit] values are validated with the device's
            k = prefix + key
            if keypath == k or keypath.startswith((f"{k}.", f"{k}[")):
                return InputError(exc.message, f"--set {text.strip()}: {keypath[len(prefix):]}")
    return exc


def _build(tree: dict, path: Path, name: str, seed: int | None, fidelity: str | None) -> Scenario:
    if seed is not None:
        set_path(tree, "scenario.seed", seed)
    if fidelity is not None:
        set_path(tree, "scenario.fidelity", fidelity)
    for top in tree:
        if top not in TOP_KEYS:
            raise InputError(f"unknown table{suggest(top, TOP_KEYS)}; tables are {list(TOP_KEYS)}", f"{name}: {top}")
    plain = {k: tree.get(k, {}) for k in ("scenario", "initial", "noise")}
    checked = validate_tree(plain, SCENARIO_SCHEMA, name)
    settings = copy.deepcopy(DEFAULTS)
    for k in settings:
        settings[k].update(checked.get(k, {}))
    if "duration_s" not in settings["scenario"]:
        raise InputError("missing key (how long to simulate, in seconds)", f"{name}: scenario.duration_s")
    device_file = settings["scenario"]["device_file"]
    base = Path(path).resolve().parent
    found = resolve_device(device_file, base)
    if found is None:
        raise InputError(f"device file {device_file!r} not found (looked in {base} and among the shipped "
                         f"devices {shipped_devices()} in {devices_dir()})", f"{name}: scenario.device_file")
    device = load_device(found)
    dev_over = copy.deepcopy(tree.get("device", {}))
    if "circuit" in tree:
        dev_over.setdefault("circuit", {})
        _deep_update(dev_over["circuit"], tree["circuit"])
    if dev_over:
        device = device.with_overrides(dev_over, name)
    temp = build_profile(_table(tree, "temperature", name), f"{name}: temperature", "start_C", "C", "degC",
                         allow_sines=False)
    rate = build_profile(_table(tree, "rate", name), f"{name}: rate", "start_dps", "dps", "deg/s", allow_sines=True)
    vref_table = {"start_factor": 1.0, **_table(tree, "vref", name)}
    vref = build_profile(vref_table, f"{name}: vref", "start_factor", "factor", "x Vref", allow_sines=False)
    for label, start in (("temperature", "start_C"), ("rate", "start_dps"), ("vref", "start_factor")):
        extra = set(_table(tree, label, name)) - {start, "segments", "points"}
        if extra:
            raise InputError(f"unknown key(s) {sorted(extra)}; expected {start}, segments or points",
                             f"{name}: {label}")
    effects = validate_effects(tree.get("effects", {}), f"{name}: effects")
    nominal = device
    device = EffectSet(effects).apply_to_device(device) if effects else device
    return Scenario(name, settings, device, temp, rate, vref, effects, nominal)


def _table(tree: dict, key: str, name: str) -> dict:
    t = tree.get(key, {})
    if not isinstance(t, dict):
        raise InputError("expected a table", f"{name}: {key}")
    return t


def _deep_update(dst: dict, src: dict) -> None:
    for k, v in src.items():
        if isinstance(v, dict) and isinstance(dst.get(k), dict):
            _deep_update(dst[k], v)
        else:
            dst[k] = v


def _checked_profile(profile, where: str) -> PiecewiseProfile:
    """``profile`` if it is a profile a scenario can hold: from t = 0, times non-decreasing, values finite."""
    if not isinstance(profile, PiecewiseProfile):
        raise InputError(f"expected a PiecewiseProfile, got {type(profile).__name__}", where)
    t, v = np.asarray(profile.times_s, dtype=float), np.asarray(profile.values, dtype=float)
    if t.ndim != 1 or t.shape != v.shape or t.size == 0:
        raise InputError(f"times and values must be two 1-D arrays of one length, got {t.shape} and {v.shape}", where)
    if t[0] != 0.0:
        raise InputError(f"the profile must start at t = 0, not {t[0]!r} s", where)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
        raise InputError("times and values must be finite", where)
    if np.any(np.diff(t) < 0):
        k = int(np.flatnonzero(np.diff(t) < 0)[0])
        raise InputError(f"times must not decrease (breakpoint {k + 2} at {t[k + 1]!r} s after {t[k]!r} s)", where)
    return profile
