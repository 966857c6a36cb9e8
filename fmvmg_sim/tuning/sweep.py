"""A grid of PI gains and temperatures evaluated on Dask.

Each task is one (Kp, Ki, temperature) point: the linearised loop's margins and step
metrics (python-control, ~0.3 s) and, optionally, a short carrier-engine step check.
By default a :class:`dask.distributed.LocalCluster` is started (2 workers x 1 thread,
one per core of the development machine) and closed afterwards; with a scheduler
address the tasks go to that existing cluster instead.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from ..device import Device

#: Columns of the sweep table, in order.
COLUMNS = ("kp", "ki_per_s", "temperature_C", "q_drive_factor", "phase_margin_deg", "gain_margin_db", "crossover_Hz",
           "bandwidth_Hz", "settling_time_s", "overshoot_pct", "u_peak_V", "feasible", "settling_simulated_s",
           "overshoot_simulated_pct")


def evaluate_point(device: Device, kp: float, ki_per_s: float, temperature_C: float, q_drive_factor: float = 1.0,
                   simulate: bool = False, limits: dict | None = None) -> dict:
    """Loop figures of one grid point (the Dask task).

    Parameters
    ----------
    device : Device
    kp, ki_per_s, temperature_C : float
    q_drive_factor : float, optional
    simulate : bool, optional
        Also run the carrier-engine 10 % step check (:func:`fmvmg_sim.tuning.verify.check_step`).
    limits : dict, optional
        ``phase_margin_deg``, ``gain_margin_db``, ``overshoot_pct`` for the ``feasible`` flag
        (defaults 60, 10, 5); the PI output limit is the device's ``u_max_V``.

    Returns
    -------
    dict
        One row with the keys of :data:`COLUMNS`.
    """
    from .linear_loop import analyze_loop, diagram_at
    lim = {"phase_margin_deg": 60.0, "gain_margin_db": 10.0, "overshoot_pct": 5.0, **(limits or {})}
    dg = diagram_at(device, temperature_C, q_drive_factor)
    m = analyze_loop(dg, kp, ki_per_s, q_drive_factor)
    stable = all(np.real(p) < 0 for p in m.closed_loop_poles)
    feasible = bool(stable and m.phase_margin_deg >= lim["phase_margin_deg"]
                    and m.gain_margin_db >= lim["gain_margin_db"] and m.overshoot_pct <= lim["overshoot_pct"]
                    and m.u_peak_V <= dg.pi.u_max_V)
    row = dict(kp=float(kp), ki_per_s=float(ki_per_s), temperature_C=float(temperature_C),
               q_drive_factor=float(q_drive_factor), phase_margin_deg=m.phase_margin_deg,
               gain_margin_db=m.gain_margin_db, crossover_Hz=m.crossover_rad_s / (2 * np.pi),
               bandwidth_Hz=m.bandwidth_Hz, settling_time_s=m.settling_time_s if stable else float("nan"),
               overshoot_pct=m.overshoot_pct if stable else float("nan"), u_peak_V=m.u_peak_V, feasible=feasible,
               settling_simulated_s=float("nan"), overshoot_simulated_pct=float("nan"))
    if simulate and stable:
        from .verify import check_step
        c = check_step(device, temperature_C, kp, ki_per_s)
        row.update(settling_simulated_s=c.settling_simulated_s, overshoot_simulated_pct=c.overshoot_simulated_pct)
    return row


@dataclass
class SweepResult:
    """Rows of a sweep and the grid they cover.

    Attributes
    ----------
    kp_values, ki_values, temperatures_C : list of float
    rows : list of dict
    cluster : str
        Where it ran (``LocalCluster(...)`` or the scheduler address).
    """

    kp_values: list
    ki_values: list
    temperatures_C: list
    rows: list = field(default_factory=list)
    cluster: str = ""

    def worst_settling_grid(self) -> np.ndarray:
        """Worst-case (over temperature) linear-model settling time on the (Ki, Kp) grid; NaN if infeasible.

        Returns
        -------
        ndarray
            Shape (len(ki_values), len(kp_values)).
        """
        out = np.full((len(self.ki_values), len(self.kp_values)), np.nan)
        for i, ki in enumerate(self.ki_values):
            for j, kp in enumerate(self.kp_values):
                rows = [r for r in self.rows if r["kp"] == kp and r["ki_per_s"] == ki]
                if rows and all(r["feasible"] for r in rows):
                    out[i, j] = max(r["settling_time_s"] for r in rows)
        return out

    def best(self) -> dict | None:
        """The feasible grid point with the smallest worst-case settling time.

        Returns
        -------
        dict or None
            ``kp``, ``ki_per_s``, ``worst_settling_time_s``.
        """
        g = self.worst_settling_grid()
        if not np.isfinite(g).any():
            return None
        i, j = np.unravel_index(np.nanargmin(g), g.shape)
        return dict(kp=self.kp_values[j], ki_per_s=self.ki_values[i], worst_settling_time_s=float(g[i, j]))

    def to_csv(self) -> str:
        """The table as CSV text (one row per grid point and temperature).

        Returns
        -------
        str
        """
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(COLUMNS)
        for r in self.rows:
            w.writerow(["" if isinstance(r[c], float) and not math.isfinite(r[c]) else r[c] for c in COLUMNS])
        return buf.getvalue()

    def as_dict(self) -> dict:
        """JSON-ready dict.

        Returns
        -------
        dict
        """
        return dict(kp_values=self.kp_values, ki_values=self.ki_values, temperatures_C=self.temperatures_C,
                    cluster=self.cluster, best=self.best(), rows=self.rows)


def run_sweep(device: Device, kp_values, ki_values, temperatures_C, simulate: bool = False, client=None,
              scheduler: str | None = None, n_workers: int = 2, threads_per_worker: int = 1,
              processes: bool = True, log=None) -> SweepResult:
    """Evaluate every (Kp, Ki, temperature) of the grid as a Dask task.

    Parameters
    ----------
    device : Device
    kp_values, ki_values, temperatures_C : sequence of float
    simulate : bool, optional
        Add a carrier-engine step check to every task (slow: ~0.5 s each).
    client : dask.distributed.Client, optional
        Use this client (nothing is started or closed).
    scheduler : str, optional
        Address of an existing scheduler (``tcp://host:8786``); ignored with ``client``.
    n_workers, threads_per_worker : int, optional
        Size of the LocalCluster started when neither ``client`` nor ``scheduler`` is given.
    processes : bool, optional
        LocalCluster workers as processes (True) or threads in this process.
    log : callable, optional

    Returns
    -------
    SweepResult
    """
    from dask.distributed import Client, LocalCluster
    log = log or (lambda m: None)
    kps = [float(k) for k in kp_values]
    kis = [float(k) for k in ki_values]
    temps = [float(t) for t in temperatures_C]
    own_cluster = own_client = None
    if client is None:
        if scheduler:
            client = own_client = Client(scheduler)
            where = str(scheduler)
        else:
            own_cluster = LocalCluster(n_workers=n_workers, threads_per_worker=threads_per_worker,
                                       processes=processes, dashboard_address=None)
            client = own_client = Client(own_cluster)
            where = f"LocalCluster({n_workers} workers x {threads_per_worker} thread, processes={processes})"
    else:
        where = str(getattr(client, "scheduler", None) and client.scheduler.address)
    try:
        points = list(itertools.product(kps, kis, temps))
        log(f"sweep: {len(points)} tasks on {where}")
        dev = client.scatter(device, broadcast=True)
        futures = [client.submit(evaluate_point, dev, kp, ki, T, 1.0, simulate, pure=False)
                   for kp, ki, T in points]
        rows = client.gather(futures)
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()
    return SweepResult(kps, kis, temps, list(rows), where)
