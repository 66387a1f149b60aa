"""The run manager: starts, drives, changes and stops the runs of the server.

Each run is an asyncio task (:meth:`RunManager._drive`) on the server's event loop.  The
numerics never run on the event loop: the task hands :meth:`RunWorker.advance` to the
run's own single-thread executor, then publishes the latest snapshot as a stream frame
(at most ``stream_max_hz`` per second) and sleeps until the next sample is due.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
import time
import uuid
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

from backend.fanout import StreamHub
from backend.frames import events_of, frame_json
from backend.repository import RunRepository
from backend.run_files import RunFiles, write_json_atomic
from backend.run_worker import ChangeRejected, LoopFactory, LoopLike, RunWorker
from backend.settings import Settings
from twin.config import FurnaceConfig
from twin.furnace.interface import FurnaceLost
from twin.scenario import OscillationSpec, Reference, Scenario

log = logging.getLogger(__name__)

ADVANCE_BUDGET_S = 0.05  # wall s of stepping per executor call: bounds frame latency at speed max


class RunNotFound(LookupError):
    pass


class RunNotActive(RuntimeError):
    """The run exists but is no longer running (409)."""


class TooManyRuns(RuntimeError):
    """``max_concurrent_runs`` runs are already going (429)."""


class LimitExceeded(ValueError):
    """The scenario asks for more than the server allows (run length, speed, a furnace it may not or cannot
    reach) (422)."""


class PlantBusy(RuntimeError):
    """Another run already drives that furnace (409)."""


class DefaultLoopFactory:
    """Builds ``twin.runs.loop.ClosedLoop`` runs sharing one radiation model (loaded once, lazily), on the
    scenario's furnace (:func:`twin.furnace.connect.open_furnace`; an OPC UA one with ``settings.opcua``)."""

    def __init__(self, settings: Settings | None = None) -> None:
        self.settings = settings or Settings()  # type: ignore[call-arg]  # defaults and environment
        self._lock = threading.Lock()
        self._radiation: dict[str, Any] = {}
        self._T_range: dict[str, tuple[float, float]] = {}

    def radiation(self, cfg: FurnaceConfig) -> Any:
        from twin.radiation import radiation_model  # type: ignore[attr-defined]  # lands with the radiation part

        key = cfg.digest()
        with self._lock:
            if key not in self._radiation:
                self._radiation[key] = radiation_model(cfg)
            return self._radiation[key]

    def reachable_range(self, cfg: FurnaceConfig) -> tuple[float, float] | None:
        """Fillet means the furnace can hold (``twin.control.reference.reachable_range``), cached per furnace;
        ``None`` if they cannot be computed (the run's own build then reports the problem)."""
        key = cfg.digest()
        if key in self._T_range:
            return self._T_range[key]
        try:
            from twin.control.reference import reachable_range
            from twin.model.discrete import discrete_model

            T_range = reachable_range(discrete_model(cfg, self.radiation(cfg), None), cfg)
        except Exception:
            log.exception("cannot compute the reachable temperature range; references are checked by the run")
            return None
        self._T_range[key] = T_range
        return T_range

    def check_reference(self, cfg: FurnaceConfig, reference: Reference) -> None:
        """Raise ``ValueError`` (``twin.control.reference.ReferenceError``) if the loop would refuse ``reference``
        at the start of a run, so ``POST /api/runs`` answers 422 instead of a run that ends in error."""
        T_range = self.reachable_range(cfg)
        if T_range is None:
            return
        from twin.control.reference import reference_trajectory

        reference_trajectory(reference, float(cfg.specimen.initial_temperature), T_range=T_range)

    def check_plant(self, cfg: FurnaceConfig, scenario: Scenario) -> None:
        """Raise (``ValueError`` / ``OSError`` with a message) if the scenario's furnace cannot be used; for a
        furnace over OPC UA this connects and finds its nodes, writing nothing (blocking: call it in a thread)."""
        from twin.furnace.connect import probe_furnace

        probe_furnace(cfg, scenario, opcua=self.settings.opcua, data_dir=self.settings.data_dir)

    def __call__(self, cfg: FurnaceConfig, scenario: Scenario) -> LoopLike:
        from twin.furnace.connect import open_furnace
        from twin.runs.loop import ClosedLoop

        radiation = self.radiation(cfg)
        furnace = open_furnace(cfg, scenario, radiation, opcua=self.settings.opcua, data_dir=self.settings.data_dir)
        try:
            # background=True: re-plans run in the loop's own thread, so a change never stalls the samples
            loop: LoopLike = ClosedLoop(cfg, scenario, radiation=radiation, furnace=furnace, background=True)
        except BaseException:
            furnace.close()
            raise
        return loop


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
    ) -> None:
        self.settings = settings
        self.cfg = cfg
        self.repo = repo
        self.loop_factory: LoopFactory = loop_factory or DefaultLoopFactory(settings)
        self.active: dict[str, ActiveRun] = {}
        self._last_frames: OrderedDict[str, str] = OrderedDict()
        self.event_loop: asyncio.AbstractEventLoop | None = None
        self._shutting_down = False

    def files(self, run_id: str) -> RunFiles:
        return RunFiles(self.settings.runs_dir / run_id)

    # ---- start ----
    def check_limits(self, scenario: Scenario) -> None:
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
        await self._check_plant(scenario)
        running = sum(1 for a in self.active.values() if a.status in ("queued", "starting", "running"))
        if running >= self.settings.max_concurrent_runs:
            raise TooManyRuns(f"{running} runs are going; this server allows "
                              f"{self.settings.max_concurrent_runs} at once: stop one or wait")
        self.event_loop = asyncio.get_running_loop()
        run_id = uuid.uuid4().hex[:12]
        files = self.files(run_id)
        files.folder.mkdir(parents=True, exist_ok=True)
        write_json_atomic(files.scenario, scenario.model_dump(mode="json"))
        self.repo.create_run(run_id, scenario.to_json())
        worker = RunWorker(run_id, scenario, self.cfg, self.settings, self.repo, files, self.loop_factory)
        run = ActiveRun(
            worker=worker,
            hub=StreamHub(queue_frames=self.settings.client_queue_frames),
            executor=concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix=f"run-{run_id}"),
            wake=asyncio.Event(),
        )
        self.active[run_id] = run
        run.task = asyncio.create_task(self._drive(run_id, run), name=f"run-{run_id}")
        log.info("run %s started: %s", run_id, scenario.to_json())
        return run_id

    async def _check_plant(self, scenario: Scenario) -> None:
        """A furnace over OPC UA: on this server's allow-list, driven by no other run, and reachable with
        every node the twin needs (:meth:`DefaultLoopFactory.check_plant`, off the event loop)."""
        plant = scenario.plant
        if plant.kind == "simulated":
            return
        from twin.furnace.connect import EndpointNotAllowed, check_endpoint

        try:
            check_endpoint(plant.endpoint, self.settings.opcua)
        except EndpointNotAllowed as exc:
            raise LimitExceeded(f"plant.endpoint: {exc}") from None
        for run_id, run in self.active.items():
            other = run.worker.scenario.plant
            if other.kind == plant.kind and getattr(other, "endpoint", None) == plant.endpoint:
                raise PlantBusy(f"run {run_id} already drives the furnace at {plant.endpoint}: stop it first")
        check = getattr(self.loop_factory, "check_plant", None)
        if callable(check):
            try:
                await asyncio.to_thread(check, self.cfg, scenario)
            except (ValueError, OSError) as exc:
                raise LimitExceeded(f"plant.endpoint: {exc}") from None

    def _set_status(self, run_id: str, run: ActiveRun, status: str, error: str | None = None) -> None:
        run.status = status
        self.repo.set_status(run_id, status, error=error)

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
        except FurnaceLost as exc:  # its data so far is kept (finalize below), the lamps commanded off if possible
            log.error("run %s: furnace lost: %s", run_id, exc)
            final, error = "plant_lost", str(exc)
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
            self.repo.set_status(run_id, final, error=error)
            if w.latest is not None:
                run.hub.publish(frame_json(w.latest, run_id=run_id, seq=w.seq, wall_time=w.latest_wall,
                                           status=final, events=unsent_events))
            run.hub.close()
            if run.hub.latest is not None:
                self._last_frames[run_id] = run.hub.latest
                while len(self._last_frames) > 64:
                    self._last_frames.popitem(last=False)
            run.executor.shutdown(wait=False)
            self.active.pop(run_id, None)
            log.info("run %s %s", run_id, final)

    # ---- control ----
    def _active(self, run_id: str) -> ActiveRun:
        run = self.active.get(run_id)
        if run is None:
            if self.repo.get(run_id) is None:
                raise RunNotFound(run_id)
            raise RunNotActive(f"run {run_id} is not running")
        return run

    def stop(self, run_id: str) -> None:
        run = self._active(run_id)
        run.worker.stop_requested.set()
        run.wake.set()

    async def change(self, run_id: str, kind: str, value: Reference | OscillationSpec) -> dict[str, Any]:
        """Queue a reference / oscillation change; wait (bounded) until the worker re-planned."""
        run = self._active(run_id)
        if run.status not in ("starting", "running") or run.worker.stop_requested.is_set():
            raise RunNotActive(f"run {run_id} is {run.status}")
        body = value.model_dump(mode="json")
        change_id = self.repo.add_change(run_id, kind, body)
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

    def hub(self, run_id: str) -> StreamHub | None:
        run = self.active.get(run_id)
        return None if run is None else run.hub

    def last_frame(self, run_id: str) -> str | None:
        run = self.active.get(run_id)
        if run is not None:
            return run.hub.latest
        return self._last_frames.get(run_id)

    def status(self, run_id: str) -> str | None:
        run = self.active.get(run_id)
        return None if run is None else run.status

    async def shutdown(self, timeout: float = 30.0) -> None:
        """Stop every run and wait for its final flush (server shutdown)."""
        self._shutting_down = True
        tasks = []
        for run in list(self.active.values()):
            run.worker.stop_requested.set()
            run.wake.set()
            if run.task is not None:
                tasks.append(run.task)
        if tasks:
            await asyncio.wait(tasks, timeout=timeout)
