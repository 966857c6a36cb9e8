"""A population study on Dask: N units drawn from the tolerances, each run over the scenario, then judged.

Each unit is one Dask task keyed by the population's seed and the unit's index, submitted with retries; a worker that dies mid-unit has its units rerun by the scheduler on
another worker, so no unit is lost. Results come back as small dicts of figures (not records), in any order,
and are put back in unit order, so the study is the same for a seed whatever the cluster.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
import uuid
from dataclasses import dataclass, field

import numpy as np

from ..runner import run_scenario
from ..scenario import Scenario
from .drivers import drivers
from .figures import FIGURES, figures_of_merit
from .spec import Spec
from .units import draw_unit, drawn_knobs, unit_scenario

#: Times a unit's task is retried after an error in it (a worker's death is rerun by the scheduler anyway).
RETRIES = 2


def run_unit(scn: Scenario, knobs: dict, seed: int, index: int) -> dict:
    """Draw and simulate one unit; its deviations and figures of merit.

    Parameters
    ----------
    scn : Scenario
    knobs : dict
        ``{knob name: tolerance}`` (:func:`fmvmg_sim.population.units.drawn_knobs`).
    seed : int
        The population's seed.
    index : int
        The unit's index.

    Returns
    -------
    dict
        ``index``, ``knobs`` (``{name: deviation}``), ``figures`` (``{figure: value}``), ``status`` (the run
        summary's) and ``cpu_s`` (the unit's CPU time in its worker).
    """
    cpu = time.process_time()
    values, noise_seed = draw_unit(knobs, seed, index)
    unit = unit_scenario(scn, values, noise_seed)
    res, summary = run_scenario(unit, progress=False)
    ref = float(unit.device_nominal.values.get("reference_temperature_C", 25.0))
    figs = figures_of_merit(res, summary, ref, unit.settings["initial"]["state"] == "rest")
    return dict(index=int(index), knobs=values, figures=figs, status=summary["status"],
                cpu_s=time.process_time() - cpu)


@dataclass
class PopulationResult:
    """The units of a population study and what they add up to.

    Attributes
    ----------
    scenario : str
        Scenario name.
    seed : int
    knobs : dict
        ``{knob name: tolerance}`` spread over the units.
    units : list of dict
        :func:`run_unit`'s output for each unit, in unit order.
    spec : Spec or None
    where : str
        The cluster the units ran on.
    wall_time_s : float
    """

    scenario: str
    seed: int
    knobs: dict
    units: list
    spec: Spec | None
    where: str
    wall_time_s: float
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def draws(self) -> np.ndarray:
        """Deviations, shape (units, knobs)."""
        return np.array([[u["knobs"][k] for k in self.knobs] for u in self.units], dtype=float).reshape(
            len(self.units), len(self.knobs))

    def figure(self, name: str) -> np.ndarray:
        """One figure of merit over the units.

        Parameters
        ----------
        name : str

        Returns
        -------
        ndarray
        """
        return np.array([u["figures"][name] for u in self.units], dtype=float)

    @property
    def passed(self) -> np.ndarray:
        """Whether each unit meets the spec (all True without a spec)."""
        if self.spec is None:
            return np.ones(len(self.units), dtype=bool)
        return self.spec.pass_table([u["figures"] for u in self.units]).all(axis=1)

    @property
    def yield_fraction(self) -> float | None:
        """Fraction of units meeting the spec (None without a spec)."""
        return None if self.spec is None else float(self.passed.mean())

    def drivers(self) -> list:
        """Knobs ranked by how much they drive the failures (:func:`fmvmg_sim.population.drivers.drivers`).

        Returns
        -------
        list of dict
        """
        limited = list(self.spec.limits) if self.spec else list(FIGURES)
        figs = {f: self.figure(f) for f in limited}
        return drivers(self.knobs, self.draws, figs, ~self.passed, limited)

    def to_dict(self) -> dict:
        """JSON-ready report: distributions, yield with its 95 % interval, failures per limit, drivers, units.

        Returns
        -------
        dict
        """
        n = len(self.units)
        dist = {}
        for f, meaning in FIGURES.items():
            v = self.figure(f)
            ok = v[np.isfinite(v)]
            dist[f] = dict(meaning=meaning, units=int(ok.size), mean=_f(ok, np.mean), std=_f(ok, np.std),
                           min=_f(ok, np.min), max=_f(ok, np.max),
                           **{f"p{q}": _f(ok, lambda a, q=q: np.percentile(a, q)) for q in (1, 5, 50, 95, 99)})
        out = dict(scenario=self.scenario, seed=self.seed, units=n, where=self.where,
                   wall_time_s=self.wall_time_s, cpu_s_per_unit=float(np.mean([u["cpu_s"] for u in self.units])),
                   knobs=self.knobs, figures=dist, statuses=_counts(u["status"] for u in self.units))
        if self.spec is not None:
            table = self.spec.pass_table([u["figures"] for u in self.units])
            k = int(self.passed.sum())
            out["spec"] = dict(name=self.spec.name, path=self.spec.path, limits=self.spec.limits)
            out["yield"] = dict(passed=k, units=n, fraction=k / n, ci95=list(wilson_interval(k, n)),
                                failures_by_limit={f: int((~table[:, j]).sum()) for j, f in enumerate(self.spec.limits)})
            out["drivers"] = self.drivers()
        out["unit_results"] = [dict(index=u["index"], status=u["status"], knobs=u["knobs"], figures=u["figures"],
                                    passed=bool(p)) for u, p in zip(self.units, self.passed)]
        return out


def _f(a: np.ndarray, fn) -> float:
    return float(fn(a)) if a.size else float("nan")


def _counts(items) -> dict:
    out: dict = {}
    for i in items:
        out[i] = out.get(i, 0) + 1
    return out


def wilson_interval(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default).

    Parameters
    ----------
    k, n : int
        Successes and trials.
    z : float, optional

    Returns
    -------
    lo, hi : float
    """
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return float(max(0.0, c - h)), float(min(1.0, c + h))


#: glibc allocator settings of the LocalCluster's worker processes: a unit allocates and frees arrays of megabytes
#: thousands of times, and with Dask's default (memory returned to the system above 64 kB) every one is mapped and
#: faulted in afresh, a third of a unit's CPU time; kept in the heap (arrays up to 32 MB, glibc's largest mmap
#: threshold; up to 256 MB of free heap kept), a unit takes about 30 % less CPU. Other allocators ignore them.
WORKER_MALLOC_ENV = {"MALLOC_TRIM_THRESHOLD_": 256 << 20, "MALLOC_MMAP_THRESHOLD_": 32 << 20}


@contextlib.contextmanager
def dask_client(client=None, scheduler: str | None = None, n_workers: int | None = None, processes: bool = True):
    """A Dask client: the one given, one on an existing scheduler, or one on a new LocalCluster (closed after).

    Parameters
    ----------
    client : dask.distributed.Client, optional
        Used as is (nothing started or closed).
    scheduler : str, optional
        Address of an existing scheduler (``tcp://host:8786``).
    n_workers : int, optional
        LocalCluster workers, one thread each (default: the cores).
    processes : bool, optional
        LocalCluster workers as processes (True) or threads of this process.

    Yields
    ------
    client : dask.distributed.Client
    where : str
        A description of the cluster.
    """
    import dask
    from dask.distributed import Client, LocalCluster
    if client is not None:
        yield client, str(client.scheduler.address)
        return
    if scheduler:
        own = Client(scheduler)
        try:
            yield own, str(scheduler)
        finally:
            own.close()
        return
    n = int(n_workers or os.cpu_count() or 1)
    with dask.config.set({f"distributed.nanny.pre-spawn-environ.{k}": v for k, v in WORKER_MALLOC_ENV.items()}):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=processes, dashboard_address=":0")
    own = Client(cluster)
    try:
        yield own, f"LocalCluster({n} workers x 1 thread, processes={processes})"
    finally:
        own.close()
        cluster.close()


def run_population(scn: Scenario, n_units: int, seed: int = 0, spec: Spec | None = None, client=None,
                   scheduler: str | None = None, n_workers: int | None = None, processes: bool = True,
                   progress: bool | None = None, on_result=None) -> PopulationResult:
    """Draw ``n_units`` units from the scenario device's tolerances and run each over the scenario on Dask.

    Parameters
    ----------
    scn : Scenario
    n_units : int
    seed : int, optional
        The population's seed (draws and noise of every unit).
    spec : Spec, optional
        Judge the units against it (yield and drivers).
    client : dask.distributed.Client, optional
        Run on this client.
    scheduler : str, optional
        Address of an existing Dask scheduler (ignored with ``client``).
    n_workers : int, optional
        Workers of the LocalCluster started otherwise (default: the cores).
    processes : bool, optional
        LocalCluster workers as processes (True) or threads.
    progress : bool, optional
        A tqdm bar on stderr over completed units (default: when stderr is a terminal).
    on_result : callable, optional
        Called with ``(client, futures, done count)`` after each completed unit (monitoring, tests).

    Returns
    -------
    PopulationResult
    """
    from dask.base import tokenize
    from dask.distributed import as_completed
    from tqdm import tqdm
    knobs = drawn_knobs(scn)
    show = sys.stderr.isatty() if progress is None else progress
    t0 = time.perf_counter()
    with dask_client(client, scheduler, n_workers, processes) as (cl, where):
        # the unit's key names its seed and index; a token of this call keeps two studies on one cluster (or a
        # study repeated before the scheduler forgot the last) apart
        token = tokenize(scn.name, scn.settings, scn.device_nominal.values, knobs, seed, uuid.uuid4().hex)[:12]
        scn_f = cl.scatter(scn, broadcast=True, hash=False)  # its own key: not freed by an earlier study's release
        futures = [cl.submit(run_unit, scn_f, knobs, seed, i, key=f"fmvmg-unit-s{seed}-u{i}-{token}",
                             pure=True, retries=RETRIES) for i in range(n_units)]
        units = [None] * n_units
        try:
            with tqdm(total=n_units, desc="units", unit="unit", disable=not show, file=sys.stderr) as bar:
                for done, fut in enumerate(as_completed(futures), 1):
                    u = fut.result()
                    units[u["index"]] = u
                    bar.update(1)
                    if on_result is not None:
                        on_result(cl, futures, done)
        finally:
            for f in futures:
                f.release()
    return PopulationResult(scn.name, int(seed), knobs, units, spec, where, time.perf_counter() - t0)
