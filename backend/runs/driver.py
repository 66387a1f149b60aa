"""Each run's asyncio task: build, step at speed, publish frames, finalise (``backend.runs.manager``).

:class:`RunDriver` is held by :class:`backend.runs.manager.RunManager` (``manager.driver``) and drives
each run: :meth:`RunDriver.drive` waits (as ``queued``) for the radiation model, checks a run posted
during the warm-up, builds the loop, then hands :meth:`backend.runs.worker.RunWorker.advance` to the run's
own single-thread executor (the numerics never run on the event loop), publishes the latest snapshot as
a stream frame (at most ``stream_max_hz`` per second; every sample when they come slower), sleeps until
the next sample is due, and at the end finalises the run with its status.  Each of the run's events goes
out once, in the frames' ``event_log``.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import time
from collections import OrderedDict
from dataclasses import dataclass, field

from backend.core.settings import Settings
from backend.runs.checks import RunChecks
from backend.runs.factory import LoopFactory
from backend.runs.types import LimitExceeded
from backend.runs.worker import RunWorker
from backend.storage.repository import DEGRADED, RunRepository
from backend.streaming.fanout import StreamHub
from backend.streaming.frames import SnapshotLike, frame_extra, frame_json
from twin.config import FurnaceConfig
from twin.control.budget import PlanCancelled
from twin.furnace.interface import FurnaceLost

log = logging.getLogger("backend.runs.manager")  # the manager's log, as before the split

ADVANCE_BUDGET_S = 0.05  # wall s of stepping per executor call: bounds frame latency at speed max
RUNNING = "running"


class _StoppedWhileQueued(Exception):
    """A run stopped before its model was ready (it ends ``stopped`` with no data)."""


@dataclass(eq=False)
class ActiveRun:
    worker: RunWorker
    hub: StreamHub
    executor: concurrent.futures.ThreadPoolExecutor
    wake: asyncio.Event
    status: str = "queued"
    #: why it ended (``twin.runs.outage.run_ending``), set with its final status: a request that sees the final
    #: status while the run is still being let go reads the reason here, as the database may not hold it yet
    ending_reason: str | None = None
    task: asyncio.Task[None] | None = None
    published_seq: int = -1
    sent_events: int = 0  # events of the worker's list already sent in frames
    started_monotonic: float = field(default_factory=time.monotonic)
    checked: bool = False  # reference and first plan checked at POST (the model was ready then)


class RunDriver:
    """The runs' tasks of a server; ``runs`` and ``last_frames`` are the manager's, shared with it."""

    def __init__(self, settings: Settings, cfg: FurnaceConfig, checks: RunChecks, loop_factory: LoopFactory,
                 repo: RunRepository, runs: dict[str, ActiveRun], last_frames: OrderedDict[str, str]) -> None:
        self.settings, self.cfg, self.checks, self.loop_factory = settings, cfg, checks, loop_factory
        self._repo, self._runs, self._last_frames = repo, runs, last_frames
        self.shutting_down = False  #: set by the manager's shutdown: runs stopped now end ``interrupted``

    def _set_status(self, run_id: str, run: ActiveRun, status: str, error: str | None = None) -> None:
        run.status = status
        self._repo.set_status(run_id, status, error=error)

    def _frame(self, run_id: str, run: ActiveRun, snap: SnapshotLike, seq: int, wall: float, status: str) -> str:
        """A frame of ``snap`` carrying the run's events that no frame has carried yet (each one once)."""
        w = run.worker
        first = run.sent_events
        new = w.events[first:]
        run.sent_events = first + len(new)
        log_entries = [{"n": first + k, "t": e.t, "text": e.text, "level": e.level,
                        "kind": e.kind} for k, e in enumerate(new)]
        return frame_json(snap, run_id=run_id, seq=seq, wall_time=wall, status=status,
                          events=[e.text for e in new], extra={"event_log": log_entries, **frame_extra(snap, w.fillet)})

    def _publish(self, run_id: str, run: ActiveRun) -> None:
        w = run.worker
        if w.latest is None or w.seq == run.published_seq:
            return
        run.published_seq = w.seq
        run.hub.publish(self._frame(run_id, run, w.latest, w.seq, w.latest_wall, run.status))

    async def drive(self, run_id: str, run: ActiveRun) -> None:
        """The run's task: build, step at speed, publish, finalise."""
        aio = asyncio.get_running_loop()
        w = run.worker
        min_interval = 1.0 / self.settings.stream_max_hz
        # real time x speed makes speed / t_s samples per second; at or below the cap, no sample is
        # skipped even when two of them fall into one advance() call (a late worker catching up)
        every_sample = w.speed is not None and w.speed / self.cfg.sampling.t_s <= self.settings.stream_max_hz
        last_pub = -1e9
        final = "finished"
        error: str | None = None
        try:
            if not await self._wait_for_model(run):
                raise _StoppedWhileQueued
            if not run.checked:  # posted during the warm-up: checked now that the models are ready
                w.notes = await self.checks.start(w.scenario)
            self._set_status(run_id, run, "starting")
            await aio.run_in_executor(run.executor, w.build)
            while True:
                adv = await aio.run_in_executor(run.executor, w.advance, ADVANCE_BUDGET_S)
                now = time.monotonic()
                if run.status == "starting" and w.latest is not None:  # running = its samples come (issue 27)
                    self._set_status(run_id, run, "running")
                if run.status in (RUNNING, DEGRADED):  # degraded while no TC reading reaches the estimate
                    blind = w.latest is not None and w.latest.blind_since is not None
                    run.status = DEGRADED if blind else RUNNING
                if every_sample:  # the samples come slower than the frame cap: send each one
                    for snap, seq, wall in adv.samples:
                        run.hub.publish(self._frame(run_id, run, snap, seq, wall, run.status))
                        run.published_seq = seq
                # events of samples that are not streamed one by one ride on the next frame: none is lost
                pending = w.seq != run.published_seq
                if pending and now - last_pub >= min_interval:
                    self._publish(run_id, run)
                    last_pub, pending = now, False
                if adv.finished:
                    break
                if w.stop_requested.is_set():
                    final = "interrupted" if self.shutting_down else "stopped"
                    error = "the server shut down during the run" if self.shutting_down else None
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
        except _StoppedWhileQueued:
            final = "interrupted" if self.shutting_down else "stopped"
            error = "the server shut down before the run started" if self.shutting_down else None
        except LimitExceeded as exc:  # the reference, checked once the model was ready
            final, error = "error", str(exc)
        except asyncio.CancelledError:
            final = "interrupted"
            error = "the server shut down during the run"
            raise
        except PlanCancelled:  # stopped (or shut down) while the first plan was being made
            final = "interrupted" if self.shutting_down else "stopped"
            error = "the server shut down during the run" if self.shutting_down else None
        except FurnaceLost as exc:  # its data so far is kept (finalize below), the lamps commanded off if possible
            log.error("run %s: furnace lost: %s", run_id, exc)
            final, error = "plant_lost", str(exc)
        except Exception as exc:
            log.exception("run %s failed", run_id)
            final, error = "error", f"{type(exc).__name__}: {exc}"
        finally:
            w.stop_requested.set()
            w.changes.cancel_all(f"the run is {final}")
            try:
                await asyncio.shield(aio.run_in_executor(run.executor, w.finalize, final, error))
            except Exception:
                log.exception("run %s: finalising failed", run_id)
            final, reason = w.ending or (final, error)  # a run that finished blind ended degraded
            run.status, run.ending_reason = final, reason
            self._repo.set_status(run_id, final, error=error, reason=reason)
            if w.latest is not None:
                run.hub.publish(self._frame(run_id, run, w.latest, w.seq, w.latest_wall, final))
            run.hub.close()
            if run.hub.latest is not None:
                self._last_frames[run_id] = run.hub.latest
                while len(self._last_frames) > 64:
                    self._last_frames.popitem(last=False)
            run.executor.shutdown(wait=False)
            self._runs.pop(run_id, None)
            log.info("run %s %s", run_id, final)

    async def _wait_for_model(self, run: ActiveRun) -> bool:
        """Wait (as ``queued``) until the radiation model is ready; False if the run was stopped meanwhile."""
        if self.loop_factory.ready(self.cfg):
            return True
        log.info("run waits for the radiation model")
        while not run.worker.stop_requested.is_set():
            if await asyncio.to_thread(self.loop_factory.wait_ready, self.cfg, 0.25):
                return True
        return False
