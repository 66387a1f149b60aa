"""The run manager: starts, drives, changes and stops the runs of the server.

Each run is an asyncio task (:meth:`backend.runs.driver.RunDriver.drive`) on the server's event loop.  The
numerics never run on the event loop: the task hands :meth:`RunWorker.advance` to the
run's own single-thread executor, then publishes the latest snapshot as a stream frame
(at most ``stream_max_hz`` per second) and sleeps until the next sample is due
(``backend.runs.driver``, mixed into the manager).

The routes and both UIs use only the public methods below (start / launch, stop, change,
set_label, delete; run, runs, changes, status, latest, in_force, scenario, live_runs,
live_series; files, hub, last_frame; call_from_thread for a UI on another
thread).  Scenarios and changes are checked (``backend.runs.checks``: the furnace's limits,
the reachable range, the reference's feasibility) before they reach a run.  Each run's
events (``RunWorker.events``) go out once each, in the frames' ``event_log``.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import dataclasses
import json
import logging
import uuid
from collections import OrderedDict
from collections.abc import Coroutine
from typing import Any, TypeVar

from backend.core.settings import Settings
from backend.runs.checks import RunChecks
from backend.runs.driver import ActiveRun, RunDriver
from backend.runs.factory import LoopFactory
from backend.runs.loop_factory import DefaultLoopFactory
from backend.runs.start_requests import RequestReused, StartRequests
from backend.runs.types import (  # noqa: F401  (re-exported: the routes and the UIs import them from here)
    InForce,
    InsufficientStorage,
    LimitExceeded,
    LiveSample,
    PlantBusy,
    RequestConflict,
    RunIsActive,
    RunNotActive,
    RunNotFound,
    Started,
    TooManyRuns,
    in_force,
)
from backend.runs.worker import RunWorker
from backend.storage.data_dir import DataDir, run_bytes
from backend.storage.repository import ACTIVE_STATUSES, DEGRADED, ChangeRow, RunRepository, RunRow, clean_label
from backend.streaming.fanout import StreamHub
from twin.config import FurnaceConfig
from twin.limits import ScenarioLimits, scenario_limits
from twin.runs.changes import ChangeRejected
from twin.runs.folder import RunFolder
from twin.scenario import FaultSpec, OpcUaPlant, OscillationSpec, Reference, Scenario

log = logging.getLogger(__name__)
T = TypeVar("T")


class RunManager:
    """All runs of one server; call its coroutines on the server's event loop."""

    def __init__(
        self,
        settings: Settings,
        cfg: FurnaceConfig,
        repo: RunRepository,
        loop_factory: LoopFactory | None = None,
        *,
        limits: ScenarioLimits | None = None,
        event_loop: asyncio.AbstractEventLoop | None = None,
    ) -> None:
        self.settings = settings
        self.cfg = cfg
        #: every scenario limit and default: the furnace's, within this server's run length and speed
        self.limits = (limits or scenario_limits(cfg)).capped(settings.max_duration_s, settings.max_speed)
        self.loop_factory: LoopFactory = loop_factory or DefaultLoopFactory(settings)
        self._repo = repo
        self._runs: dict[str, ActiveRun] = {}
        self._last_frames: OrderedDict[str, str] = OrderedDict()
        self._loop = event_loop
        #: where runs stream their recording live (``--rerun-connect``, or the server's rerun web viewer)
        self.live_url: str | None = settings.rerun_connect
        self._requests: StartRequests[Started] = StartRequests()  # a repeated POST gets the same run
        self.checks = RunChecks(cfg, self.limits, settings, self.loop_factory)
        #: each run's task (build, step at speed, publish frames, finalise)
        self.driver = RunDriver(settings, cfg, self.checks, self.loop_factory, repo, self._runs, self._last_frames)
        #: the data directory's usage, quota, free space and retention (backend.storage.data_dir)
        self.disk = DataDir(settings.data_dir, settings.data_quota_mb, settings.min_free_mb, settings.retention_days)

    def files(self, run_id: str) -> RunFolder:
        return RunFolder(self.settings.runs_dir / run_id)

    # ---- start ----
    def model_ready(self) -> bool:
        """The loop factory can build a run now (its radiation models are loaded); a factory without a
        warm-up is always ready."""
        return bool(self.loop_factory.ready(self.cfg))

    def warm_up(self) -> Any:
        """The radiation model's :class:`backend.runs.loop_factory.WarmUpStatus`; ``None`` for a factory without one."""
        return self.loop_factory.warm_up_status(self.cfg)

    def retry_warm_up(self) -> bool:
        """Start the radiation model's warm-up again after it failed; False if it has not failed."""
        return bool(self.loop_factory.retry_warm_up(self.cfg))

    async def start(self, scenario: Scenario) -> str:
        """Register and launch a run; returns its id (:meth:`launch` without a request id)."""
        return (await self.launch(scenario)).run_id

    async def launch(self, scenario: Scenario, request_id: str | None = None) -> Started:
        """Start a run once per ``request_id``: the same id again (a double click, a retried request) gets the
        run the first request started, or its refusal, instead of a second run."""
        if request_id is None:
            return await self._launch(scenario)
        try:
            started, replayed = await self._requests.once(request_id, scenario.to_json(),
                                                          lambda: self._launch(scenario))
        except RequestReused as exc:
            raise RequestConflict(str(exc)) from None
        return dataclasses.replace(started, replayed=replayed)

    async def _launch(self, scenario: Scenario) -> Started:
        """Register and launch a run at once.  While the radiation models warm up the run waits as ``queued``:
        only the limits (and the furnace it names) are checked now, its reference (reachable, feasible, a plan
        within this server's time and memory) when the models are ready, and a refusal then ends it in
        ``error``; afterwards all of it is a :class:`LimitExceeded` here.  The plan starts from what earlier
        runs of this furnace learnt (:mod:`twin.control.calibration_memory`) unless the scenario says."""
        scenario = self.with_memory(scenario)
        checked = self.model_ready()
        if checked:
            notes = await self.checks.start(scenario)
        else:
            self.checks.limits_of(scenario)
            notes = ()
        self._check_plant_free(scenario)
        await self.checks.plant(scenario)
        running = sum(1 for a in self._runs.values() if a.status in (*ACTIVE_STATUSES, DEGRADED))
        if running >= self.settings.max_concurrent_runs:
            raise TooManyRuns(f"{running} runs are going; this server allows "
                              f"{self.settings.max_concurrent_runs} at once: stop one or wait")
        await asyncio.to_thread(self.disk.apply_retention, self._repo, self.settings.runs_dir)
        need = run_bytes(self.cfg, scenario.duration, self.settings.recording_image_interval_s)
        need += sum(run_bytes(self.cfg, a.worker.scenario.duration) for a in self._runs.values())  # still to come
        problem = await asyncio.to_thread(self.disk.room_for, need)
        if problem is not None:
            raise InsufficientStorage(problem)
        self._loop = asyncio.get_running_loop()
        run_id = uuid.uuid4().hex[:12]
        files = self.files(run_id)
        files.folder.mkdir(parents=True, exist_ok=True)
        files.write_scenario(scenario)
        self._repo.create_run(run_id, scenario.to_json())
        worker = RunWorker(run_id, scenario, self.cfg, self.settings, self._repo, files, self.loop_factory,
                           disk=self.disk, notes=notes, live_url=self.live_url)
        run = ActiveRun(
            worker=worker,
            hub=StreamHub(queue_frames=self.settings.client_queue_frames),
            executor=concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix=f"run-{run_id}"),
            wake=asyncio.Event(),
            checked=checked,
        )
        self._runs[run_id] = run
        run.task = asyncio.create_task(self.driver.drive(run_id, run), name=f"run-{run_id}")
        log.info("run %s started: %s", run_id, scenario.to_json())
        return Started(run_id, notes)

    def with_memory(self, scenario: Scenario) -> Scenario:
        """The scenario with the furnace's learnt parameters for its plan (``control.plan_parameters``)."""
        from twin.control.calibration_memory import with_memory

        return with_memory(scenario, self.settings.data_dir, self.cfg)

    def _check_plant_free(self, scenario: Scenario) -> None:
        """:class:`PlantBusy` if another run of this server drives the scenario's furnace over OPC UA."""
        plant = scenario.plant
        if plant.kind == "simulated":
            return
        for run_id, run in self._runs.items():
            other = run.worker.scenario.plant
            if isinstance(other, OpcUaPlant) and other.endpoint == plant.endpoint:
                raise PlantBusy(f"run {run_id} already drives the furnace at {plant.endpoint}: stop it first")

    # ---- control ----
    def _active(self, run_id: str) -> ActiveRun:
        run = self._runs.get(run_id)
        if run is None:
            if self._repo.get(run_id) is None:
                raise RunNotFound(run_id)
            raise RunNotActive(f"run {run_id} is not running")
        return run

    def stop(self, run_id: str) -> None:
        run = self._active(run_id)
        run.worker.stop_requested.set()
        run.wake.set()

    async def change(self, run_id: str, kind: str,
                     value: Reference | OscillationSpec | list[FaultSpec]) -> dict[str, Any]:
        """Queue a reference / oscillation / faults change; wait (bounded) until it is in force (``applied``),
        a later change replaced it (``superseded``), or the wait is over (``pending``: the outcome comes in
        the run's events and its changes).  A change that cannot be planned (or faults a furnace cannot
        take) raises :class:`ChangeRejected`; one outside the furnace's limits, or a reference the furnace
        cannot follow, before it reaches the run."""
        run = self._active(run_id)
        self.checks.change_limits(value)
        live = ("starting", "running", DEGRADED) if kind == "faults" else ("running", DEGRADED)
        no_sample = kind != "faults" and run.worker.latest is None
        if run.status not in live or run.worker.stop_requested.is_set() or no_sample:
            # a reference / oscillation while queued / starting: no estimate yet to check it from, and no plan to
            # change (issue 27: one sent while starting was applied at t = 7.6 s without the start's feasibility
            # check); faults apply to the furnace at once, from the start
            state = "stopping" if run.worker.stop_requested.is_set() else run.status
            why = ": live changes are taken once it runs (from its first sample on)" \
                if state in ("queued", "starting", "running") else ""
            raise RunNotActive(f"run {run_id} is {state}{why}")
        notes: tuple[str, ...] = ()
        if kind == "reference":  # from the current estimate: the mean now, from the next sample on
            w, snap = run.worker, run.worker.latest
            notes = await self.checks.reference_change(
                value, w.scenario.duration, w.oscillation,  # type: ignore[arg-type]
                float(snap.T_mean_hat) if snap is not None else None,
                float(snap.t) + self.cfg.sampling.t_s if snap is not None else 0.0)
        body = ({"faults": [f.model_dump(mode="json") for f in value]} if isinstance(value, list)
                else value.model_dump(mode="json"))
        change_id = self._repo.add_change(run_id, kind, body)
        fut = run.worker.changes.submit(kind, value, change_id, notes)
        run.wake.set()
        try:
            result = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(fut)),
                                            timeout=self.settings.change_timeout_s)
        except TimeoutError:
            return {"id": change_id, "kind": kind, "status": "pending", "body": body, "warnings": list(notes)}
        except ChangeRejected:
            raise
        return {"id": change_id, "kind": kind, "body": body, **result, "warnings": list(notes)}

    # ---- the runs list: label and delete ----
    def set_label(self, run_id: str, label: str | None) -> RunRow:
        """Name a run (``None`` or blank: no name; ``repository.clean_label``)."""
        self.run(run_id)
        try:
            self._repo.set_label(run_id, clean_label(label))
        except ValueError as exc:
            raise LimitExceeded(f"label: {exc}") from None
        return self.run(run_id)

    def delete(self, run_id: str) -> None:
        """Remove a run that has ended, with its files (:class:`RunIsActive` while it is going)."""
        row = self.run(run_id)
        if run_id in self._runs or row.status in ACTIVE_STATUSES:
            raise RunIsActive(f"run {run_id} is {self.status(run_id) or row.status}: stop it before deleting it")
        self.files(run_id).remove()
        self._repo.delete_run(run_id)
        self._last_frames.pop(run_id, None)
        log.info("run %s deleted", run_id)

    # ---- what the routes and the UIs read ----
    def run(self, run_id: str) -> RunRow:
        """The run's record (status as stored; :meth:`status` has the live one); :class:`RunNotFound` if none."""
        row = self._repo.get(run_id)
        if row is None:
            raise RunNotFound(f"no run with id {run_id!r}")
        return row

    def runs(self, limit: int = 200) -> list[RunRow]:
        """Every run, newest first."""
        return self._repo.list_runs(limit)

    def changes(self, run_id: str) -> list[ChangeRow]:
        """The reference / oscillation changes requested while the run ran, oldest first."""
        return self._repo.changes(run_id)

    def status(self, run_id: str) -> str | None:
        """The live status of a run this server drives (``None`` if it does not drive it)."""
        run = self._runs.get(run_id)
        return None if run is None else run.status

    def ending_reason(self, run_id: str) -> str | None:
        """Why a run this server drives ended, once it has (its status final, the run not yet let go); else ``None``."""
        run = self._runs.get(run_id)
        return None if run is None else run.ending_reason

    def live_runs(self) -> list[str]:
        """Ids of the runs this server drives (queued, starting, running), newest first."""
        return sorted(self._runs, key=lambda k: self._runs[k].started_monotonic, reverse=True)

    def latest(self, run_id: str) -> LiveSample | None:
        """The latest sample of a run this server drives; ``None`` if it drives none or no sample yet."""
        run = self._runs.get(run_id)
        if run is None:
            return None
        w = run.worker
        snap, seq = w.latest, w.seq
        return None if snap is None else LiveSample(snap, seq, run.status, w.latest_wall)

    def scenario(self, run_id: str) -> dict[str, Any]:
        """The run's scenario as it was started (JSON object)."""
        run = self._runs.get(run_id)
        if run is not None:
            return run.worker.scenario.model_dump(mode="json")
        return self.run(run_id).scenario

    def in_force(self, run_id: str) -> InForce:
        """The reference and oscillation the run uses now; for an ended run, the last ones in force."""
        run = self._runs.get(run_id)
        if run is not None:
            w = run.worker
            return InForce(w.reference.model_dump(mode="json"), w.oscillation.model_dump(mode="json"),
                           [f.model_dump(mode="json") for f in w.faults])
        return in_force(self.run(run_id).scenario, self.changes(run_id))

    def fault_events(self, run_id: str) -> list[dict[str, Any]]:
        """The run's fault events (injected, cleared, detected: ``{"t", "text"}``), oldest first."""
        run = self._runs.get(run_id)
        if run is not None:
            return list(run.worker.fault_events)
        path = self.files(run_id).faults
        try:
            events: list[dict[str, Any]] = json.loads(path.read_text())["events"]
            return events
        except (OSError, ValueError, KeyError):
            return []

    def live_series(self, run_id: str) -> dict[str, Any] | None:
        """The time series of a run this server drives, up to its latest sample (``timeseries.npz`` layout);
        ``None`` if it drives no such run or it has no sample yet.  Any thread."""
        run = self._runs.get(run_id)
        return None if run is None else run.worker.live_series()

    def hub(self, run_id: str) -> StreamHub | None:
        run = self._runs.get(run_id)
        return None if run is None else run.hub

    def last_frame(self, run_id: str) -> str | None:
        run = self._runs.get(run_id)
        if run is not None:
            return run.hub.latest
        return self._last_frames.get(run_id)

    def call_from_thread(self, coro: Coroutine[Any, Any, T], timeout: float | None = None) -> T:
        """Run one of the manager's coroutines from another thread (a UI's) on the server's event loop
        and return its result (its exception is raised here); ``timeout`` defaults to the change timeout."""
        if self._loop is None or self._loop.is_closed():
            coro.close()
            raise RuntimeError("the server is not ready")
        future = asyncio.run_coroutine_threadsafe(coro, self._loop)
        return future.result(timeout=self.settings.change_timeout_s if timeout is None else timeout)

    async def shutdown(self, timeout: float = 30.0) -> None:
        """Stop every run and wait for its final flush (server shutdown)."""
        self.driver.shutting_down = True
        tasks = []
        for run in list(self._runs.values()):
            run.worker.stop_requested.set()
            run.wake.set()
            if run.task is not None:
                tasks.append(run.task)
        if tasks:
            await asyncio.wait(tasks, timeout=timeout)
