"""Simulation results: named channels on one time base, written to the record format at the edge."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .record import Record

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
