"""The slow noises of a run, drawn the same way by both engines.

The demodulation-phase flicker enters the loop, drawn at the output rate and held over each output interval
by both engines (so its content depends neither on the engine nor on its step: a 1/f noise drawn at the step
rate would carry power up to half the step rate into the output samples); the output flicker and the rate
random walk are added to the rate output at the output rate, in volts
through the nominal scale factor. They are drawn from the run's generator before any fast noise, in
a fixed order (phase flicker, output flicker, rate random walk), so that they do not depend on how the
engine cuts the run into calls and a seed gives one record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import noise as noisegen


@dataclass
class SlowNoises:
    """The slow noises of one run.

    Attributes
    ----------
    phase_rad : ndarray
        Demodulation-reference phase flicker, one value per output sample (rad).
    output_flicker_V : ndarray
        Flicker of the rate output, one value per output sample (V).
    rate_random_walk_V : ndarray
        Rate random walk of the rate output, one value per output sample (V).
    """

    phase_rad: np.ndarray
    output_flicker_V: np.ndarray
    rate_random_walk_V: np.ndarray


def draw_slow_noises(scn, rng: np.random.Generator, n_out: int, dt_out_s: float) -> SlowNoises:
    """Draw the slow noises of a run of ``scn`` from ``rng`` (switched by the scenario's ``[noise]`` table).

    Parameters
    ----------
    scn : fmvmg_sim.scenario.Scenario
    rng : numpy.random.Generator
        The run's generator, before any other draw.
    n_out : int
        Output samples.
    dt_out_s : float
        Output interval.

    Returns
    -------
    SlowNoises
        Zeros for the noises switched off.
    """
    nz, values = scn.noise, scn.device.values["noise"]
    phase = (noisegen.flicker(n_out, 1.0 / dt_out_s, values["flicker_phase_rad2"], rng)
             if nz["flicker"] else np.zeros(n_out))
    sf_nom = scn.device_nominal.nominal_scale_factor_V_per_dps
    out_flicker = (noisegen.flicker(n_out, 1.0 / dt_out_s, values["flicker_output_dps2"], rng) * sf_nom
                   if nz["flicker"] else np.zeros(n_out))
    rrw = (noisegen.random_walk(n_out, 1.0 / dt_out_s, values["rate_random_walk_dps_per_sqrt_s"], rng) * sf_nom
           if nz["rate_random_walk"] else np.zeros(n_out))
    return SlowNoises(phase, out_flicker, rrw)
