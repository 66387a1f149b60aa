"""The run manager: starts, drives, changes and stops the runs of the server.

Each run is an asyncio task (:meth:`RunManager._drive`) on the server's event loop.  The
numerics never run on the event loop: the task hands :meth:`RunWorker.advance` to the
run's own single-thread executor, then publishes the latest snapshot as a stream frame
(at most ``stream_max_hz`` per second) and sleeps until the next sample is due.

The routes and both UIs use only the public methods below (start, stop, change; run, runs,
changes, status, latest, in_force, scenario, live_runs; files, hub, last_frame;
call_from_thread for a UI on another thread).  Scenarios and changes are checked against the
furnace's limits (``twin.limits``) before they reach a run.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import time
import uuid
from collections import OrderedDict
from collections.abc import Coroutine
from dataclasses import dataclass, field
from typing import Any, TypeVar

from pydantic import ValidationError

from backend.fanout import StreamHub
from backend.frames import SnapshotLike, events_of, frame_json
from backend.loop_factory import DefaultLoopFactory
from backend.repository import ACTIVE_STATUSES, ChangeRow, RunRepository, RunRow
from backend.run_files import RunFiles, write_json_atomic
from backend.run_worker import ChangeRejected, LoopFactory, RunWorker
from backend.settings import Settings
from backend.storage import DataDir, run_bytes
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanCancelled
from twin.limits import ScenarioLimits, scenario_limits
from twin.scenario import OscillationSpec, Reference, Scenario, check

log = logging.getLogger(__name__)
T = TypeVar("T")

ADVANCE_BUDGET_S = 0.05  # wall s of stepping per executor call: bounds frame latency at speed max


class RunNotFound(LookupError):
    pass


class RunNotActive(RuntimeError):
    """The run exists but is no longer running (409)."""


class TooManyRuns(RuntimeError):
    """``max_concurrent_runs`` runs are already going (429)."""


class InsufficientStorage(RuntimeError):
    """The data directory's quota or the disk's free space has no room for the run (507)."""


class LimitExceeded(ValueError):
    """The scenario asks for more than the furnace or the server allows (amplitude, run length, speed) (422)."""


@dataclass(frozen=True)
class LiveSample:
    """The latest sample of a running run: its snapshot, sequence number and the run's status."""

    snapshot: SnapshotLike
    seq: int
    status: str


@dataclass(frozen=True)
class InForce:
    """The reference and oscillation a run uses now (after live changes), as JSON objects."""

    reference: dict[str, Any]
    oscillation: dict[str, Any]


def in_force(scenario: dict[str, Any], changes: list[ChangeRow]) -> InForce:
    """The scenario's reference and oscillation, replaced by each applied change in turn (an ended run)."""
    current = {"reference": scenario.get("reference") or {}, "oscillation": scenario.get("oscillation") or {}}
    for ch in changes:
        if ch.status == "applied" and ch.kind in current:
            current[ch.kind] = ch.body
    return InForce(**current)


def _say(exc: ValidationError) -> str:
    """A pydantic error as one line that names each field."""
    return "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg'].removeprefix('Value error, ')}"
                     for e in exc.errors())


@dataclass(eq=False)
class ActiveRun:
    worker: RunWorker
    hub: StreamHub
    executor: concurrent.futures.ThreadPoolExecutor
    wake: asyncio.Event
    status: str = "queued"
    task: asyncio.Task[None] | None = None
    published_seq: int = -1
    started_monotonic: float = field(default_factory=time.monotonic)


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
        self.loop_factory: LoopFactory = loop_factory or DefaultLoopFactory()
        self._repo = repo
        self._runs: dict[str, ActiveRun] = {}
        self._last_frames: OrderedDict[str, str] = OrderedDict()
        self._loop = event_loop
        self._shutting_down = False
        #: the data directory's usage, quota, free space and retention (backend.storage)
        self.disk = DataDir(settings.data_dir, settings.data_quota_mb, settings.min_free_mb, settings.retention_days)

    def files(self, run_id: str) -> RunFiles:
        return RunFiles(self.settings.runs_dir / run_id)

    # ---- start ----
    def check_limits(self, scenario: Scenario) -> None:
        """Raise :class:`LimitExceeded` if the scenario lies outside the furnace's or this server's limits."""
        try:
            check(scenario, self.limits)
        except ValidationError as exc:
            raise LimitExceeded(_say(exc)) from None
        s = self.settings
        problems = []
        if scenario.duration > s.max_duration_s:
            problems.append(f"duration: {scenario.duration:g} s exceeds this server's limit of "
                            f"{s.max_duration_s:g} s")
        if scenario.speed != "max" and float(scenario.speed) > s.max_speed:
            problems.append(f"speed: {scenario.speed:g} exceeds this server's limit of {s.max_speed:g}")
        if problems:
            raise LimitExceeded("; ".join(problems))

    async def start(self, scenario: Scenario) -> str:
        """Register and launch a run; returns its id."""
        self.check_limits(scenario)
        check = getattr(self.loop_factory, "check_reference", None)
        if callable(check):  # off the event loop: the first call may load the radiation model
            try:
                await asyncio.to_thread(check, self.cfg, scenario.reference)
            except ValueError as exc:
                raise LimitExceeded(f"reference: {exc}") from None
        check_plan = getattr(self.loop_factory, "check_plan", None)
        if callable(check_plan):  # the first plan within this server's time and memory (twin.control.budget)
            budget = PlanBudget(self.settings.plan_max_s, self.settings.plan_max_mb)
            try:
                await asyncio.to_thread(check_plan, self.cfg, scenario, budget)
            except ValueError as exc:
                raise LimitExceeded(f"reference: {exc}") from None
        running = sum(1 for a in self._runs.values() if a.status in ACTIVE_STATUSES)
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
        write_json_atomic(files.scenario, scenario.model_dump(mode="json"))
        self._repo.create_run(run_id, scenario.to_json())
        worker = RunWorker(run_id, scenario, self.cfg, self.settings, self._repo, files, self.loop_factory,
                           disk=self.disk)
        run = ActiveRun(
            worker=worker,
            hub=StreamHub(queue_frames=self.settings.client_queue_frames),
            executor=concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix=f"run-{run_id}"),
            wake=asyncio.Event(),
        )
        self._runs[run_id] = run
        run.task = asyncio.create_task(self._drive(run_id, run), name=f"run-{run_id}")
        log.info("run %s started: %s", run_id, scenario.to_json())
        return run_id

    def _set_status(self, run_id: str, run: ActiveRun, status: str, error: str | None = None) -> None:
        run.status = status
        self._repo.set_status(run_id, status, error=error)

    def _publish(self, run_id: str, run: ActiveRun, events: list[str] | None = None) -> None:
        w = run.worker
        if w.latest is None or w.seq == run.published_seq:
            return
        run.published_seq = w.seq
        run.hub.publish(frame_json(w.latest, run_id=run_id, seq=w.seq, wall_time=w.latest_wall,
                                   status=run.status, events=events))

    async def _drive(self, run_id: str, run: ActiveRun) -> None:
        """The run's task: build, step at speed, publish, finalise."""
        aio = asyncio.get_running_loop()
        w = run.worker
        min_interval = 1.0 / self.settings.stream_max_hz
        # real time x speed makes speed / t_s samples per second; at or below the cap, no sample is
        # skipped even when two of them fall into one advance() call (a late worker catching up)
        every_sample = w.speed is not None and w.speed / self.cfg.sampling.t_s <= self.settings.stream_max_hz
        last_pub = -1e9
        # events of samples that are not streamed one by one ride on the next frame: none is lost
        unsent_events: list[str] = []
        final = "finished"
        error: str | None = None
        try:
            self._set_status(run_id, run, "starting")
            await aio.run_in_executor(run.executor, w.build)
            self._set_status(run_id, run, "running")
            while True:
                adv = await aio.run_in_executor(run.executor, w.advance, ADVANCE_BUDGET_S)
                now = time.monotonic()
                if every_sample:  # the samples come slower than the frame cap: send each one
                    for snap, seq, wall in adv.samples:
                        run.hub.publish(frame_json(snap, run_id=run_id, seq=seq, wall_time=wall, status=run.status))
                        run.published_seq = seq
                else:
                    for snap, _, _ in adv.samples:
                        unsent_events.extend(events_of(snap.events))
                pending = w.seq != run.published_seq
                if pending and now - last_pub >= min_interval:
                    self._publish(run_id, run, unsent_events)
                    unsent_events = []
                    last_pub, pending = now, False
                if adv.finished:
                    break
                if w.stop_requested.is_set():
                    final = "interrupted" if self._shutting_down else "stopped"
                    error = "the server shut down during the run" if self._shutting_down else None
                    break
                wait = adv.wait_s
                if pending:
                    wait = min(wait, max(last_pub + min_interval - now, 0.0)) if wait > 0 else 0.0
                if wait > 0:
                    run.wake.clear()
                    try:
                        await asyncio.wait_for(run.wake.wait(), timeout=wait)
                    except TimeoutError:
                        pass
                else:
                    await asyncio.sleep(0)  # let the websockets send
        except asyncio.CancelledError:
            final = "interrupted"
            error = "the server shut down during the run"
            raise
        except PlanCancelled:  # stopped (or shut down) while the first plan was being made
            final = "interrupted" if self._shutting_down else "stopped"
            error = "the server shut down during the run" if self._shutting_down else None
        except Exception as exc:
            log.exception("run %s failed", run_id)
            final, error = "error", f"{type(exc).__name__}: {exc}"
        finally:
            w.stop_requested.set()
            w.cancel_changes(f"the run is {final}")
            try:
                await asyncio.shield(aio.run_in_executor(run.executor, w.finalize))
            except Exception:
                log.exception("run %s: finalising failed", run_id)
            run.status = final
            self._repo.set_status(run_id, final, error=error)
            if w.latest is not None:
                run.hub.publish(frame_json(w.latest, run_id=run_id, seq=w.seq, wall_time=w.latest_wall,
                                           status=final, events=unsent_events))
            run.hub.close()
            if run.hub.latest is not None:
                self._last_frames[run_id] = run.hub.latest
                while len(self._last_frames) > 64:
                    self._last_frames.popitem(last=False)
            run.executor.shutdown(wait=False)
            self._runs.pop(run_id, None)
            log.info("run %s %s", run_id, final)

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

    async def change(self, run_id: str, kind: str, value: Reference | OscillationSpec) -> dict[str, Any]:
        """Queue a reference / oscillation change; wait (bounded) until it is in force (``applied``), a later
        change replaced it (``superseded``), or the wait is over (``pending``: the outcome comes in the
        run's events and its changes).  A change that cannot be planned raises :class:`ChangeRejected`.

        A change outside the furnace's limits is refused (:class:`ChangeRejected`) before it reaches the run."""
        run = self._active(run_id)
        try:
            check(value, self.limits)
        except ValidationError as exc:
            raise ChangeRejected(_say(exc)) from None
        if run.status not in ("starting", "running") or run.worker.stop_requested.is_set():
            raise RunNotActive(f"run {run_id} is {run.status}")
        body = value.model_dump(mode="json")
        change_id = self._repo.add_change(run_id, kind, body)
        fut = run.worker.submit_change(kind, value, change_id)
        run.wake.set()
        try:
            result = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(fut)),
                                            timeout=self.settings.change_timeout_s)
        except TimeoutError:
            return {"id": change_id, "kind": kind, "status": "pending", "body": body}
        except ChangeRejected:
            raise
        return {"id": change_id, "kind": kind, "body": body, **result}

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
        return None if snap is None else LiveSample(snap, seq, run.status)

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
            return InForce(w.reference.model_dump(mode="json"), w.oscillation.model_dump(mode="json"))
        return in_force(self.run(run_id).scenario, self.changes(run_id))

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
        self._shutting_down = True
        tasks = []
        for run in list(self._runs.values()):
            run.worker.stop_requested.set()
            run.wake.set()
            if run.task is not None:
                tasks.append(run.task)
        if tasks:
            await asyncio.wait(tasks, timeout=timeout)
