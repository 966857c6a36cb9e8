"""A scenario changed through Scenario.replace: the scenario the same --set overrides load, and bad changes refused."""

from __future__ import annotations

import numpy as np
import pytest

from fmvmg_sim.envelope.engine import run_envelope
from fmvmg_sim.errors import InputError
from fmvmg_sim.profiles import PiecewiseProfile
from fmvmg_sim.scenario import load_scenario
from tests.conftest import scenario_text
from tests.test_records_unchanged import digest

#: A noisy envelope scenario with a temperature ramp given as points, and one effect.
BODY = "[effects]\nquadrature_drift = { beta_per_K = 0.002 }\n"
TEMPERATURE = "points = [[0.0, 20.0], [30.0, 26.0]]"


@pytest.fixture
def path(tmp_path):
    p = tmp_path / "replace_me.toml"
    p.write_text(scenario_text("replace_me", duration_s=30.0, output_rate_Hz=50.0, state="rest",
                               temperature=TEMPERATURE, fidelity="carrier", noise=True, seed=2) + BODY)
    return p


def test_replaced_settings_and_profile_give_the_record_of_the_overridden_file(path):
    sets = ["scenario.duration_s=12.0", "scenario.seed=7", "scenario.fidelity=envelope", "initial.state=steady",
            "scenario.output_rate_Hz=20.0", "temperature.points=[[0.0, 25.0], [6.0, 25.0], [12.0, 31.0]]"]
    loaded = load_scenario(path, overrides=sets)
    base = load_scenario(path)
    changed = base.replace(scenario={"duration_s": 12.0, "seed": 7, "fidelity": "envelope", "output_rate_Hz": 20.0},
                           initial={"state": "steady"},
                           temperature=PiecewiseProfile(np.array([0.0, 6.0, 12.0]), np.array([25.0, 25.0, 31.0]), []))
    assert changed.settings == loaded.settings
    assert base.settings["scenario"]["duration_s"] == 30.0 and base.settings["initial"]["state"] == "rest"
    assert digest(run_envelope(changed, progress=False)) == digest(run_envelope(loaded, progress=False))


def test_replaced_effects_fold_into_the_nominal_device(path):
    base = load_scenario(path)
    loaded = load_scenario(path, overrides=["effects.q_factor_drift.q_tc_per_K=0.005"])
    changed = base.replace(effects=dict(base.effects, q_factor_drift={"q_tc_per_K": 0.005}))
    assert changed.effects == loaded.effects
    assert changed.device.values == loaded.device.values
    assert changed.device_nominal is base.device_nominal
    none = base.replace(effects={})
    assert none.device.values == base.device_nominal.values and none.effects == {}


def test_a_given_device_is_used_as_given(path):
    base = load_scenario(path)
    other = base.device_nominal.with_overrides({"mechanics": {"q_drive": 4.0e4}}, "test")
    changed = base.replace(device=other, effects={})
    assert changed.device is other and changed.device_nominal is base.device_nominal and changed.effects == {}


@pytest.mark.parametrize("changes, where", [
    (dict(scenario={"fidelity": "fast"}), "scenario.fidelity"),
    (dict(scenario={"duraton_s": 5.0}), "scenario.duraton_s"),
    (dict(scenario={"duration_s": -1.0}), "scenario.duration_s"),
    (dict(noise={"brownian": "yes"}), "noise.brownian"),
    (dict(effects={"duffing": {"k3_rel": 1.0}}), "effects"),
    (dict(device={"mechanics": {}}), "device"),
    (dict(temperature=np.zeros(3)), "temperature"),
    (dict(rate=PiecewiseProfile(np.array([0.0, 2.0, 1.0]), np.zeros(3), [])), "rate"),
    (dict(rate=PiecewiseProfile(np.array([1.0, 2.0]), np.zeros(2), [])), "rate"),
    (dict(vref_factor=PiecewiseProfile(np.array([0.0, 1.0]), np.array([1.0, np.nan]), [])), "vref_factor"),
])
def test_bad_changes_are_refused_by_name(path, changes, where):
    base = load_scenario(path)
    with pytest.raises(InputError) as err:
        base.replace(**changes)
    assert where in str(err.value)
