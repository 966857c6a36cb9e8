"""The Dask gain sweep: a tiny grid on an in-process LocalCluster, through the API and the CLI (--scheduler)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from fmvmg_sim.device import load_device
from fmvmg_sim.tuning.sweep import COLUMNS, run_sweep

distributed = pytest.importorskip("dask.distributed")


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cl:
        yield cl


def test_sweep_on_local_cluster(cluster):
    dev = load_device("fmvmg_a")
    with distributed.Client(cluster) as client:
        res = run_sweep(dev, [60.0, 130.0, 400.0], [300.0, 500.0], [-40.0, 85.0], client=client)
    assert len(res.rows) == 12
    g = res.worst_settling_grid()
    assert g.shape == (2, 3)
    # Kp = 400 breaks the output limit (u0 + 400 x 0.045 V > 8 V): infeasible
    assert np.isnan(g[:, 2]).all()
    # faster with the higher feasible gain; the worst case is over both temperatures
    assert np.all(g[:, 1] < g[:, 0])
    best = res.best()
    assert best["kp"] == 130.0
    rows = [r for r in res.rows if r["kp"] == 130.0 and r["ki_per_s"] == best["ki_per_s"]]
    assert best["worst_settling_time_s"] == max(r["settling_time_s"] for r in rows)
    table = list(csv.reader(res.to_csv().splitlines()))
    assert tuple(table[0]) == COLUMNS and len(table) == 13


@pytest.mark.filterwarnings("ignore:Port .* is already in use")
def test_cli_sweep_with_scheduler(cluster, tmp_path, capsys):
    from fmvmg_sim.cli.main import main
    rc = main(["tune", "--sweep", "--scheduler", cluster.scheduler_address, "--kp-grid", "50", "150", "2",
               "--ki-grid", "300", "600", "2", "--temperatures", "25", "-o", str(tmp_path), "--json"])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["rows"]) == 4 and data["best"]["kp"] == 150.0
    for name in ("sweep.csv", "sweep.json", "sweep_heatmap.png"):
        assert (tmp_path / name).is_file()
    assert main(["tune", "--sweep", "--kp-grid", "50", "10", "3"]) == 2
    assert "--kp-grid" in capsys.readouterr().err
