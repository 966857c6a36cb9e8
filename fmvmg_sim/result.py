"""Simulation results: named channels on one time base, written to the record format at the edge.

:func:`engine_result` is where both engines turn their outputs into a result: the slow output
noises and the DAQ's quantisation added, the record channels, metadata and info every run has.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import noise as noisegen
from .record import Record
from .slow_noise import SlowNoises

#: Record channels every engine fills (docs/formats.md section 2).
RECORD_CHANNELS = ("time_s", "temperature_C", "rate_dps", "rate_V", "rate_true_dps", "quadrature_V",
                   "drive_amplitude_V", "agc_effort_V", "drive_frequency_Hz")


@dataclass
class SimResult:
    """The outcome of a run, like python-control's ``TimeResponseData``: labelled channels.

    Attributes
    ----------
    channels : dict of str to ndarray
        Record channels (:data:`RECORD_CHANNELS`).
    internal : dict of str to ndarray
        Channels a real gyro does not give (mechanical amplitude in m, die temperature, ...).
    info : dict
        Engine, timings, steps per cycle, nominal scale factor, analytic predictions.
    metadata : dict
        ``# key: value`` lines for the record file.
    summary : dict
        What ``summary.json`` holds (filled by :func:`fmvmg_sim.simulate`; empty from an engine).
    """

    channels: dict
    internal: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)

    @property
    def time_s(self) -> np.ndarray:
        """Sample times."""
        return self.channels["time_s"]

    def __getitem__(self, name: str) -> np.ndarray:
        if name in self.channels:
            return self.channels[name]
        return self.internal[name]

    def to_record(self) -> Record:
        """The record (docs/formats.md section 2) of this result.

        Returns
        -------
        Record
        """
        return Record({k: self.channels[k] for k in RECORD_CHANNELS}, dict(self.metadata))


def engine_result(scn, engine: str, t_s: np.ndarray, outputs: dict, slow: SlowNoises, internal: dict,
                  info: dict, wall0_s: float) -> SimResult:
    """The result of an engine's run of ``scn``.

    The rate output gets the slow output noises (flicker, rate random walk) and, with the
    quadrature output, the DAQ's quantisation; ``rate_dps`` is ``rate_V`` over the nominal
    device's scale factor. The case temperature and the applied rate are the scenario's over
    each sample (their left limits at its end).

    Parameters
    ----------
    scn : fmvmg_sim.scenario.Scenario
    engine : str
        ``carrier`` or ``envelope``.
    t_s : ndarray
        End of each output interval.
    outputs : dict
        The engine's per-sample means: ``rate_V`` and ``quadrature_V`` (before the output noises and
        the quantisation), ``drive_amplitude_V``, ``agc_effort_V``, ``drive_frequency_Hz``.
    slow : SlowNoises
    internal : dict
        Channels a real gyro does not give.
    info : dict
        The engine's own entries (steps, compiled, ...), after the ones every run has.
    wall0_s : float
        ``time.perf_counter()`` at the start of the run.

    Returns
    -------
    SimResult
    """
    dev = scn.device
    lsb = dev.values["noise"]["quantization_lsb_V"] if scn.noise["quantization"] else 0.0
    sf_nom = scn.device_nominal.nominal_scale_factor_V_per_dps
    rate_V = noisegen.quantize(outputs["rate_V"] + slow.output_flicker_V + slow.rate_random_walk_V, lsb)
    channels = dict(
        time_s=t_s, temperature_C=np.asarray(scn.temperature.left_limit(t_s), dtype=float),
        rate_dps=rate_V / sf_nom, rate_V=rate_V, rate_true_dps=np.asarray(scn.rate.left_limit(t_s), dtype=float),
        quadrature_V=noisegen.quantize(outputs["quadrature_V"], lsb),
        drive_amplitude_V=outputs["drive_amplitude_V"], agc_effort_V=outputs["agc_effort_V"],
        drive_frequency_Hz=outputs["drive_frequency_Hz"],
    )
    full_info = dict(engine=engine, nominal_scale_factor_V_per_dps=sf_nom, simulated_time_s=float(t_s[-1]), **info,
                     wall_time_s=time.perf_counter() - wall0_s)
    meta = {"device": dev.name, "source": "simulation", "engine": engine, "scenario": scn.name,
            "seed": str(scn.seed), "nominal_scale_factor_V_per_dps": f"{sf_nom:.9g}"}
    return SimResult(channels, internal, full_info, meta)
