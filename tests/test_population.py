"""Population studies: deterministic units, yield against a spec, the driving tolerance found, a dead worker's
units rerun, bad spec files refused with the key named."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.errors import InputError
from fmvmg_sim.population.figures import FIGURES
from fmvmg_sim.population.spec import Spec, load_spec
from fmvmg_sim.population.study import run_population, wilson_interval
from fmvmg_sim.population.units import draw_unit, drawn_knobs
from fmvmg_sim.scenario import load_scenario

#: A short two-temperature run (25 C then 35 C) at 1 Hz with the envelope engine: every unit in well under a second.
SHORT = """
[scenario]
name = "pop_short"
device_file = "fmvmg_a"
duration_s = 500.0
output_rate_Hz = 1.0
seed = 1
fidelity = "envelope"
[initial]
state = "steady"
[temperature]
start_C = 25.0
segments = [ { hold_s = 200.0 }, { ramp_to_C = 35.0, rate_C_per_min = 10.0 }, { hold_s = 240.0 } ]
[rate]
start_dps = 0.0
"""
N = 8
pytestmark = pytest.mark.xdist_group("population")  # one worker shares the module's cluster and population


def _figures(pop):
    """The units' figures of merit as an array (NaN compares equal in numpy's testing)."""
    return np.array([[u["figures"][f] for f in FIGURES] for u in pop.units])


@pytest.fixture(scope="module")
def short_path(tmp_path_factory):
    p = tmp_path_factory.mktemp("pop") / "short.toml"
    p.write_text(SHORT)
    return p


@pytest.fixture(scope="module")
def client():
    from dask.distributed import Client, LocalCluster
    cluster = LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0")
    cl = Client(cluster)
    yield cl
    cl.close()
    cluster.close()


@pytest.fixture(scope="module")
def population(short_path, client):
    return run_population(load_scenario(short_path), N, seed=5, client=client, progress=False)


def test_units_are_deterministic_for_a_seed(short_path, client, population):
    again = run_population(load_scenario(short_path), N, seed=5, client=client, progress=False)
    assert [u["knobs"] for u in again.units] == [u["knobs"] for u in population.units]
    np.testing.assert_array_equal(_figures(again), _figures(population))
    # a unit does not depend on the population's size, and another seed draws other units
    assert draw_unit(population.knobs, 5, 3) == (population.units[3]["knobs"], draw_unit(population.knobs, 5, 3)[1])
    assert draw_unit(population.knobs, 6, 3)[0] != population.units[3]["knobs"]
    # the draws stay within the tolerances
    tol = np.array(list(population.knobs.values()))
    assert np.all(np.abs(population.draws) <= tol)


def test_zero_tolerance_gives_identical_units(short_path, client):
    scn = load_scenario(short_path, [f"device.tolerance.{k}=0" for k in drawn_knobs(load_scenario(short_path))]
                        + [f"noise.{n}=false" for n in ("brownian", "electronic", "flicker", "quantization",
                                                        "rate_random_walk")])
    assert drawn_knobs(scn) == {}
    pop = run_population(scn, 3, seed=1, client=client, progress=False)
    figs = _figures(pop)
    np.testing.assert_array_equal(figs[0], figs[1])
    np.testing.assert_array_equal(figs[0], figs[2])
    assert np.isfinite(pop.figure("bias_25C_dps")).all() and np.isfinite(pop.figure("bias_tc_dps_per_K")).all()


def test_yield_is_one_for_a_loose_spec_and_zero_for_an_impossible_one(population):
    population.spec = Spec("loose", {"bias_25C_dps": {"max_abs": 1e6}, "scale_factor_V_per_dps": {"min": 0.0}})
    assert population.yield_fraction == 1.0
    population.spec = Spec("impossible", {"bias_25C_dps": {"max_abs": 1e-12}})
    assert population.yield_fraction == 0.0
    rep = population.to_dict()
    assert rep["yield"]["passed"] == 0 and rep["yield"]["failures_by_limit"] == {"bias_25C_dps": N}
    population.spec = None


def test_figures_follow_the_device(population):
    # the scale factor spreads with the sense gain (+-5 %) and the bias changes between the two holds
    sf = population.figure("scale_factor_V_per_dps")
    assert np.all(np.isfinite(sf)) and 0.01 < np.std(sf) / np.mean(sf) < 0.2
    assert np.all(np.isfinite(population.figure("bias_tc_dps_per_K")))


def test_the_dominant_tolerance_is_named(short_path, client):
    # the demodulation phase error (times the ~200 deg/s quadrature) dominates the bias when its tolerance is large
    scn = load_scenario(short_path, ["device.tolerance.demod_phase_mrad=100"])
    pop = run_population(scn, 10, seed=2, client=client, progress=False)
    bias = pop.figure("bias_25C_dps")
    pop.spec = Spec("bias", {"bias_25C_dps": {"max_abs": float(np.median(np.abs(bias)))}})
    top = pop.drivers()[0]
    assert top["knob"] == "demod_phase_mrad"
    assert abs(top["spearman"]["bias_25C_dps"]) > 0.8


def test_wilson_interval():
    lo, hi = wilson_interval(50, 100)
    assert lo == pytest.approx(0.4038, abs=1e-3) and hi == pytest.approx(0.5962, abs=1e-3)
    assert wilson_interval(0, 10)[0] == 0.0


@pytest.mark.parametrize("text,key", [
    ("[limits]\nbias_25c_dps = { max_abs = 1.0 }\n", "limits.bias_25c_dps"),
    ("[limits]\nbias_25C_dps = { max_absolute = 1.0 }\n", "limits.bias_25C_dps.max_absolute"),
    ("[limits]\narw_deg_per_sqrt_h = { max = \"3\" }\n", "limits.arw_deg_per_sqrt_h.max"),
    ("[limits]\nbias_tc_dps_per_K = { min = 1.0, max = 0.0 }\n", "limits.bias_tc_dps_per_K"),
    ("[spec]\nname = \"x\"\n", "limits"),
])
def test_bad_spec_exits_2_naming_the_key(tmp_path, short_path, capsys, text, key):
    spec = tmp_path / "spec.toml"
    spec.write_text(text)
    with pytest.raises(InputError, match=key.replace(".", r"\.")):
        load_spec(spec)
    out = tmp_path / "out"
    rc = main(["population", str(short_path), "--units", "2", "--spec", str(spec), "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and key in err and str(spec) in err
    assert not out.exists()


def test_shipped_spec_loads():
    from fmvmg_sim.population.spec import default_spec_path
    spec = load_spec(default_spec_path())
    assert "bias_25C_dps" in spec.limits


def test_cli_writes_the_folder_whole(tmp_path, short_path, capsys, monkeypatch):
    import fmvmg_sim.population.study as study
    out = tmp_path / "pop"
    real = study.dask_client

    def one_thread(client=None, scheduler=None, n_workers=None, processes=True):
        return real(client, scheduler, 1, False)
    monkeypatch.setattr(study, "dask_client", one_thread)
    rc = main(["population", str(short_path), "--units", "3", "--seed", "4", "-o", str(out), "--json",
               "--no-plots", "--no-progress"])
    rep = json.loads(capsys.readouterr().out)
    assert rc == 0 and rep["units"] == 3 and "yield" in rep
    assert sorted(p.name for p in out.iterdir()) == [".fmvmg-output.json", "population.json", "units.csv"]
    assert len((out / "units.csv").read_text().splitlines()) == 4


def test_a_dead_workers_units_rerun(short_path, population):
    # two worker processes; four units; the first time a worker is busy with a unit, it is killed (SIGKILL): the scheduler
    # reruns its unit elsewhere and the population comes back whole and the same as on an undisturbed cluster
    from dask.distributed import Client, LocalCluster
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    cl = Client(cluster)
    killed = []

    def kill_a_busy_worker(client, futures, done):
        if killed:
            return
        busy = [w for w, keys in client.processing().items() if keys]
        if busy:
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            killed.append(client.processing()[busy[0]])
            os.kill(pid, signal.SIGKILL)
    try:
        pop = run_population(load_scenario(short_path), 4, seed=5, client=cl, progress=False,
                             on_result=kill_a_busy_worker)
    finally:
        cl.close()
        cluster.close()
    assert killed and killed[0]
    np.testing.assert_array_equal(_figures(pop), _figures(population)[:4])  # a unit is the same in any population
