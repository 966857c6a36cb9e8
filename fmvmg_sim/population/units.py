"""Units drawn from a device's tolerances: each knob's deviation, and the unit's scenario.

A unit is the nominal device with every *unit* and *law* knob of :mod:`fmvmg_sim.uncertainty` moved by a
deviation drawn uniformly within its tolerance (``[-t, +t]``). The *channel* knobs describe a data
acquisition, not the sensor, and stay at 0. Unit ``i`` of a population with seed ``s`` draws its deviations
and its noise seed from ``numpy.random.default_rng([s, i])``, so a unit is the same whichever worker runs it
and whatever the population size.
"""

from __future__ import annotations


import numpy as np

from ..diagnosis.parameters import apply_nominal
from ..scenario import Scenario
from ..uncertainty import KNOBS, tolerances

#: Knob groups a population spreads.
UNIT_GROUPS = ("unit", "law")


def drawn_knobs(scn: Scenario) -> dict:
    """The knobs a population spreads for a scenario's device, with their tolerances.

    Parameters
    ----------
    scn : Scenario

    Returns
    -------
    dict
        ``{knob name: tolerance}`` of the unit and law knobs with a tolerance above 0, in
        :data:`fmvmg_sim.uncertainty.KNOBS` order.
    """
    tol = tolerances(scn.device_nominal)
    return {k.name: tol[k.name] for k in KNOBS if k.group in UNIT_GROUPS and tol[k.name] > 0.0}


def draw_unit(knobs: dict, seed: int, index: int) -> tuple[dict, int]:
    """One unit's deviations and noise seed.

    Parameters
    ----------
    knobs : dict
        ``{knob name: tolerance}`` (:func:`drawn_knobs`).
    seed : int
        The population's seed.
    index : int
        The unit's index.

    Returns
    -------
    values : dict
        ``{knob name: deviation}``, each uniform in ``[-tolerance, +tolerance]``.
    noise_seed : int
        The seed of the unit's noise.
    """
    rng = np.random.default_rng([int(seed), int(index)])
    values = {name: float(rng.uniform(-t, t)) for name, t in knobs.items()}
    return values, int(rng.integers(0, 2**31 - 1))


def unit_scenario(scn: Scenario, values: dict, noise_seed: int) -> Scenario:
    """The scenario run by one unit: ``scn`` with the unit's device and noise seed.

    The knobs act on the data-sheet device; the scenario's effects are then folded in as for the nominal
    device, and the unit's own scale factor converts its rate output to deg/s (a unit calibrated in scale
    factor, as a production line does).

    Parameters
    ----------
    scn : Scenario
    values : dict
        ``{knob name: deviation}``.
    noise_seed : int

    Returns
    -------
    Scenario
    """
    from ..effects import EffectSet
    nominal = apply_nominal(scn.device_nominal, values)
    device = EffectSet(scn.effects).apply_to_device(nominal) if scn.effects else nominal
    return scn.replace(scenario={"seed": int(noise_seed)}, device=device, device_nominal=nominal)
