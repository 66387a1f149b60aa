"""One run of the campaign, wherever it runs: in this process, or on a Dask worker of the study engine's cluster
(:func:`twin.studies.cluster.study_client`: a LocalCluster on every core, or ``--scheduler`` to go wide).

A :class:`CampaignRun` is small and plain (the furnace travels once per worker, scattered, as in a study).
:func:`run_campaign_run` builds the simulated furnace and the closed loop, runs it to its end into the run's
folder (:func:`twin.experiments.run.execute_run`: ``metrics.json``, ``timeseries.npz``, figures, the sinks'
files) and computes the model's open-loop error on the run's inputs, so everything a run costs happens on the
worker.  A worker on this machine writes the folder in place; a worker that may be on another machine
(``ship``) writes it into a temporary folder and sends its files back, and the client writes them
(:func:`write_shipped`).

A worker never ray-traces: it loads the furnace's tables from its radiation cache (the client makes sure they
are there first, :func:`ensure_tables`) and keeps them for all its runs (:func:`furnace_tables`); a worker
whose cache lacks them fails its runs with a message that says what to do.  The initial plans are shared
between the runs of one worker process as the serial campaign shares them (``ClosedLoop(plan_cache=...)``), and
the runs that share a plan go to one worker together (:func:`group_by_plan`), where the runs that differ only in
TC4's place are one closed loop (:func:`run_campaign_group`, :mod:`twin.experiments.campaign_places`).
"""

from __future__ import annotations

import logging
import tempfile
import threading
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.config import FurnaceConfig, config_from_dict

if TYPE_CHECKING:
    from twin.experiments.run import SinkFactory

log = logging.getLogger(__name__)

_LOCK = threading.Lock()
#: per worker process, by furnace digest: (config, the model's radiation, the simulated furnace's own or None)
_TABLES: dict[tuple[str, bool], tuple[FurnaceConfig, Any, Any]] = {}
#: per worker process, by furnace digest: the initial plans of identical starts (the serial campaign's cache)
_PLANS: dict[str, dict[Any, Any]] = {}


class TablesNotCached(RuntimeError):
    """A worker's radiation cache lacks a table of the furnace: the message says which and what to run."""


@dataclass(frozen=True)
class CampaignRun:
    """What travels to a worker with each run (the furnace goes once per worker, scattered)."""

    name: str  #: the experiment
    seed: int
    folder: str  #: the run's folder as the client sees it
    scenario_json: str
    furnace_digest: str
    own_truth: bool  #: the scenario's truth is "independent": the worker loads the simulated furnace's own table
    figures: bool = True
    ship: bool = False  #: write into a temporary folder and send the files back (a worker on another machine)
    keep_series: bool = False  #: send the time series back (seed 0: the campaign's homogeneity figure)


def _cache_paths(cfg: FurnaceConfig, truth: bool) -> list[Path]:
    from twin.furnace.simulated.truth import truth_radiation_config
    from twin.radiation.cache import cache_path

    paths = [cache_path(cfg)]
    if truth:
        paths.append(cache_path(truth_radiation_config(cfg), symmetric=True))
    return paths


def ensure_tables(cfg: FurnaceConfig, truth: bool) -> None:
    """Ray-trace (once, here, with a progress bar) a table the runs will need and the cache lacks: the twin's
    model's and, for the honest truth, the simulated furnace's own; workers then only load them."""
    from twin.furnace.simulated.truth import truth_radiation
    from twin.radiation import radiation_model

    model, *own = _cache_paths(cfg, truth)
    if not model.exists():
        log.info("radiation tables of this furnace are not cached yet: computing them once before the campaign")
        radiation_model(cfg, progress=True)
    if own and not own[0].exists():
        log.info("the simulated furnace's own radiation table (its truth) is not cached yet: computing it once")
        truth_radiation(cfg, progress=True)


def furnace_tables(digest: str, furnace: dict[str, Any], truth: bool) -> tuple[FurnaceConfig, Any, Any]:
    """(config, the model's radiation, the truth's radiation or None) of a furnace, loaded from this process's
    radiation cache once and kept; :class:`TablesNotCached` instead of a ray trace when a table is missing."""
    with _LOCK:
        hit = _TABLES.get((digest, truth))
        if hit is not None:
            return hit
        from twin.furnace.simulated.truth import truth_radiation
        from twin.radiation import radiation_model

        cfg = config_from_dict(furnace)
        if cfg.digest() != digest:
            raise ValueError(f"furnace digest mismatch: the client sent {digest}, the worker computes "
                             f"{cfg.digest()} (different furnace-twin versions on client and worker?)")
        missing = [str(p) for p in _cache_paths(cfg, truth) if not p.exists()]
        if missing:
            raise TablesNotCached(f"radiation table(s) not in this worker's cache: {', '.join(missing)} (run "
                                  "`furnace-twin precompute` with the same --config on the worker's machine, or "
                                  "set FURNACE_TWIN_CACHE to a copy of the client's cache)")
        entry = (cfg, radiation_model(cfg), truth_radiation(cfg) if truth else None)
        _TABLES[(digest, truth)] = entry
        return entry


def run_campaign_run(
    task: CampaignRun,
    furnace: dict[str, Any] | None = None,
    sink_factories: Iterable[SinkFactory] = (),
    *,
    local: tuple[FurnaceConfig, Any, Any] | None = None,
    plan_cache: dict[Any, Any] | None = None,
) -> dict[str, Any]:
    """Run one campaign run to its end; returns ``{"name", "seed", "metrics", "model_error", "out", "files",
    "series"}`` (``files``: relative path -> bytes when ``task.ship``; ``series``: the time series with
    ``task.keep_series``).  In this process ``local`` is (config, radiation, truth radiation) and
    ``plan_cache`` the campaign's; on a worker they come from the worker's own caches.  A run that fails raises,
    as in the serial campaign."""
    return run_campaign_group([task], furnace, sink_factories, local=local, plan_cache=plan_cache)[0]


def run_campaign_group(
    tasks: list[CampaignRun],
    furnace: dict[str, Any] | None = None,
    sink_factories: Iterable[SinkFactory] = (),
    *,
    local: tuple[FurnaceConfig, Any, Any] | None = None,
    plan_cache: dict[Any, Any] | None = None,
) -> list[dict[str, Any]]:
    """Run campaign runs to their end, as :func:`run_campaign_run` each, in the order of ``tasks``.  Runs that
    differ only in TC4's place (one specimen mode and seed, :func:`twin.experiments.campaign_places.shares_loop`)
    are one closed loop, its samples written into each place's folder with TC4 there; otherwise (or if the
    shared run did something its places cannot replay) each run has its own loop."""
    from twin.experiments.campaign_places import SharedRunRefused, TC4Places, shares_loop
    from twin.limits import scenario_limits
    from twin.scenario import Scenario

    if local is None:
        if furnace is None:
            raise ValueError("run_campaign_run needs the furnace (a worker) or local tables (in process)")
        cfg, rad, own = furnace_tables(tasks[0].furnace_digest, furnace, tasks[0].own_truth)
        plans = _PLANS.setdefault(tasks[0].furnace_digest, {})
    else:
        cfg, rad, own = local
        plans = plan_cache if plan_cache is not None else {}
    tables = (cfg, rad, own)
    scenarios = [Scenario.model_validate_json(t.scenario_json, context={"limits": scenario_limits(cfg)})
                 for t in tasks]
    sinks = list(sink_factories)
    if len(tasks) == 1 or not shares_loop(scenarios):
        return [_run_alone(t, s, tables, plans, sinks) for t, s in zip(tasks, scenarios, strict=True)]
    places = TC4Places(cfg, scenarios[1:])
    loop = _closed_loop(tasks[0], scenarios[0], tables, plans, places)
    first = _execute(tasks[0], loop, tables, [*sinks, places.sink])
    try:
        others = places.loops()
    except SharedRunRefused as exc:
        log.info("campaign: %s, seed %d: the TC4 places run alone (%s)", tasks[0].name, tasks[0].seed, exc)
        return [first, *(_run_alone(t, s, tables, plans, sinks) for t, s in zip(tasks[1:], scenarios[1:],
                                                                                 strict=True))]
    out = [first]
    for task, place in zip(tasks[1:], others, strict=True):
        log.info("campaign: %s, seed %d: TC4 at %s of the shared run", task.name, task.seed, place.scenario.tc4)
        # the model's open-loop error reads the run's inputs and true field only: the shared run's
        out.append(_execute(task, place, tables, sinks, model_error=first["model_error"]))
    return out


def _closed_loop(task: CampaignRun, scenario: Any, tables: tuple[FurnaceConfig, Any, Any], plans: dict[Any, Any],
                 places: Any = None) -> Any:
    """The simulated furnace and the closed loop of a run (with ``places``: TC4 read at its places too)."""
    from twin.control.budget import BATCH_MAX_WALL_S, PlanBudget
    from twin.furnace.simulated import SimulatedFurnace
    from twin.runs.loop import ClosedLoop

    cfg, rad, own = tables
    log.info("campaign: %s, seed %d (truth %s)", task.name, task.seed, scenario.truth)
    sim = SimulatedFurnace.for_scenario(cfg, scenario, rad, truth_radiation=own if scenario.truth == "independent"
                                        else None, other_tc4=() if places is None else places.places)
    loop = ClosedLoop(cfg, scenario, rad, furnace=sim, plan_cache=plans, budget=PlanBudget(BATCH_MAX_WALL_S),
                      on_estimate=None if places is None else places.on_estimate)
    if places is not None:
        places.attach(loop)
    return loop


def _run_alone(task: CampaignRun, scenario: Any, tables: tuple[FurnaceConfig, Any, Any], plans: dict[Any, Any],
               sinks: list[Any]) -> dict[str, Any]:
    return _execute(task, _closed_loop(task, scenario, tables, plans), tables, sinks)


def _execute(task: CampaignRun, loop: Any, tables: tuple[FurnaceConfig, Any, Any], sinks: list[Any], *,
             model_error: dict[str, Any] | None = None) -> dict[str, Any]:
    """A loop (a ``ClosedLoop`` or a TC4 place's) run to its end into the task's folder; the run's result."""
    from twin.experiments.model_error import open_loop_model_error
    from twin.experiments.run import execute_run
    from twin.jsonable import jsonable

    cfg, rad, _own = tables
    if task.ship:
        with tempfile.TemporaryDirectory(prefix="furnace-twin-campaign-") as tmp:
            folder = Path(tmp) / Path(task.folder).name  # the same name: a sink may name its file after it
            result = execute_run(loop, folder, sink_factories=sinks, figures=task.figures)
            files = {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}
    else:
        result = execute_run(loop, Path(task.folder), sink_factories=sinks, figures=task.figures)
        files = None
    ts = loop.timeseries()
    return {
        "name": task.name,
        "seed": task.seed,
        "metrics": jsonable({k: v for k, v in result.items() if k not in ("out", "status", "status_reason")}),
        "model_error": model_error if model_error is not None else jsonable(open_loop_model_error(cfg, ts, rad)),
        "out": task.folder,
        "files": files,
        "series": ts if task.keep_series else None,
    }


def run_campaign_runs(tasks: list[CampaignRun], furnace: dict[str, Any], sink_factories: Iterable[SinkFactory] = (),
                      ) -> list[dict[str, Any]]:
    """The runs of one group (:func:`group_by_plan`) on one worker: one closed loop for their TC4 places
    (:func:`run_campaign_group`); runs that cannot share it share at least their initial plan, about half the
    cost of a short run."""
    return run_campaign_group(tasks, furnace, sink_factories)


def group_by_plan(tasks: list[CampaignRun]) -> list[list[CampaignRun]]:
    """The runs grouped by what their initial plan depends on (``ClosedLoop``'s plan cache key: the oscillation,
    the reference and the first readings, i.e. the specimen mode and the seed; the TC4 position does not enter),
    the oscillating groups (the longer runs) first; within a group in campaign order."""
    groups: dict[tuple[str, int], list[CampaignRun]] = {}
    for t in tasks:
        groups.setdefault((t.name.split("_tc4_")[0], t.seed), []).append(t)
    return sorted(groups.values(), key=lambda g: not g[0].name.startswith("oscillating"))


def write_shipped(run: dict[str, Any]) -> None:
    """Write the files a worker sent back into the run's folder (nothing when it wrote them in place)."""
    files = run.get("files")
    if not files:
        return
    folder = Path(run["out"])
    for rel, data in files.items():
        path = folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
