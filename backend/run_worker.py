"""One run's closed loop, driven from its own worker thread.

:class:`RunWorker` owns the ``twin.runs.loop.ClosedLoop`` of a run and everything the run
writes: the ``.rrd`` recording, ``timeseries.npz``, ``metrics.json`` and its database
rows.  The run manager's async task calls :meth:`RunWorker.advance` in the run's thread;
each call steps the loop as far as the speed allows (real time x factor, or as fast as
possible) for at most a small wall-time budget and returns the latest snapshot.  A loop on a
real-time furnace (``paced_by_furnace``) is not paced here: its step waits, in this thread, for the
furnace's next sample, so the furnace's clock drives the run and the server's event loop never waits.
Reference / oscillation changes are queued and applied between two samples, in this
thread (they re-plan, which may take seconds), never on the event loop.
"""

from __future__ import annotations

import concurrent.futures
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from backend.frames import SnapshotLike, json_safe, scalar_values
from backend.recording import RecordingSink
from backend.repository import RunRepository
from backend.run_files import RunFiles, write_json_atomic, write_npz_atomic
from backend.settings import Settings
from twin.config import FurnaceConfig
from twin.scenario import OscillationSpec, Reference, Scenario

log = logging.getLogger(__name__)


class LoopLike(Protocol):
    """The part of ``twin.runs.loop.ClosedLoop`` the backend uses (docs/interfaces.md)."""

    @property
    def done(self) -> bool: ...

    @property
    def paced_by_furnace(self) -> bool: ...  # a real-time furnace: step() waits for its samples

    def step(self) -> Any: ...

    def set_reference(self, ref: Reference) -> None: ...

    def set_oscillation(self, spec: OscillationSpec) -> None: ...

    def timeseries(self) -> dict[str, Any]: ...

    def metrics(self) -> dict[str, Any]: ...


LoopFactory = Callable[[FurnaceConfig, Scenario], LoopLike]


class ChangeRejected(ValueError):
    """The loop refused a change (e.g. an unreachable reference)."""


@dataclass(frozen=True)
class Advance:
    """Result of one :meth:`RunWorker.advance` call."""

    snapshot: SnapshotLike | None
    seq: int
    wall_time: float
    steps: int
    samples: tuple[tuple[SnapshotLike, int, float], ...]  # (snapshot, seq, wall time) of this call
    finished: bool
    wait_s: float


@dataclass
class _Change:
    kind: str  # "reference" | "oscillation"
    value: Any
    change_id: int
    future: concurrent.futures.Future[dict[str, Any]]


class RunWorker:
    """Steps one closed loop at the scenario's speed and persists what it produces."""

    def __init__(
        self,
        run_id: str,
        scenario: Scenario,
        cfg: FurnaceConfig,
        settings: Settings,
        repo: RunRepository,
        files: RunFiles,
        loop_factory: LoopFactory,
    ) -> None:
        self.run_id = run_id
        self.scenario = scenario
        self.cfg = cfg
        self.settings = settings
        self.repo = repo
        self.files = files
        self._factory = loop_factory
        self.loop: LoopLike | None = None
        self.recording: RecordingSink | None = None
        self.speed: float | None = None if scenario.speed == "max" else float(scenario.speed)
        self.reference: Reference = scenario.reference
        self.oscillation: OscillationSpec = scenario.oscillation
        self.latest: SnapshotLike | None = None
        self.latest_wall = 0.0
        self.seq = 0
        self.stop_requested = threading.Event()
        self._changes: deque[_Change] = deque()
        self._changes_lock = threading.Lock()
        self._origin_wall = 0.0
        self._origin_t = 0.0
        self._last_flush = 0.0

    # ---- set-up (worker thread) ----
    def build(self) -> None:
        """Create the closed loop (this solves the first feedforward: seconds) and the recording."""
        self.files.folder.mkdir(parents=True, exist_ok=True)
        self.recording = RecordingSink(
            self.cfg, self.run_id, self.files.recording,
            tc_positions=self.cfg.tc_positions(self.scenario.tc4),
            image_interval=self.settings.recording_image_interval_s,
        )
        self.loop = self._factory(self.cfg, self.scenario)
        self._rebase(0.0)
        self._last_flush = time.monotonic()

    def _rebase(self, t: float) -> None:
        """Real-time pacing restarts from now at simulated time ``t`` (after set-up or a re-plan)."""
        self._origin_wall = time.monotonic()
        self._origin_t = t

    # ---- changes (any thread submits, worker applies) ----
    def submit_change(self, kind: str, value: Any, change_id: int) -> concurrent.futures.Future[dict[str, Any]]:
        fut: concurrent.futures.Future[dict[str, Any]] = concurrent.futures.Future()
        with self._changes_lock:
            self._changes.append(_Change(kind, value, change_id, fut))
        return fut

    def _apply_changes(self) -> bool:
        assert self.loop is not None
        applied = False
        while True:
            with self._changes_lock:
                if not self._changes:
                    return applied
                ch = self._changes.popleft()
            # the first sample that uses the change (the loop counts a new reference's times from it)
            t = float(self.latest.t) + self.cfg.sampling.t_s if self.latest is not None else 0.0
            t0 = time.monotonic()
            try:
                if ch.kind == "reference":
                    self.loop.set_reference(ch.value)
                    self.reference = ch.value
                else:
                    self.loop.set_oscillation(ch.value)
                    self.oscillation = ch.value
            except ValueError as exc:
                self.repo.finish_change(ch.change_id, "rejected", t, str(exc))
                ch.future.set_exception(ChangeRejected(str(exc)))
                continue
            except Exception as exc:  # the run goes on with its old plan
                log.exception("run %s: %s change failed", self.run_id, ch.kind)
                self.repo.finish_change(ch.change_id, "failed", t, repr(exc))
                ch.future.set_exception(exc)
                continue
            replan_s = time.monotonic() - t0
            log.info("run %s: %s changed at t=%.1f s (re-plan %.2f s)", self.run_id, ch.kind, t, replan_s)
            self.repo.finish_change(ch.change_id, "applied", t, None)
            ch.future.set_result({"status": "applied", "applied_t": t, "replan_s": replan_s})
            applied = True

    def cancel_changes(self, reason: str) -> None:
        with self._changes_lock:
            pending, self._changes = list(self._changes), deque()
        for ch in pending:
            self.repo.finish_change(ch.change_id, "cancelled", None, reason)
            ch.future.set_exception(ChangeRejected(reason))

    # ---- stepping (worker thread) ----
    def _finished(self) -> bool:
        assert self.loop is not None
        if self.loop.done:
            return True
        return self.latest is not None and float(self.latest.t) >= self.scenario.duration - 1e-9

    def advance(self, budget_s: float) -> Advance:
        """Step while samples are due (speed) for at most ``budget_s`` wall seconds."""
        assert self.loop is not None
        start = time.monotonic()
        steps = 0
        samples: list[tuple[SnapshotLike, int, float]] = []
        t_s = self.cfg.sampling.t_s
        wait = 0.0
        while not self.stop_requested.is_set() and not self._finished():
            if self._apply_changes():
                self._rebase(float(self.latest.t) if self.latest is not None else 0.0)
            next_t = (float(self.latest.t) if self.latest is not None else 0.0) + t_s
            if self.speed is not None and not self.loop.paced_by_furnace:
                due = self._origin_wall + (next_t - self._origin_t) / self.speed
                wait = due - time.monotonic()
                if wait > 0:
                    break
            snap = self.loop.step()
            self.latest, self.latest_wall = snap, time.time()
            self.seq += 1
            steps += 1
            samples.append((snap, self.seq, self.latest_wall))
            if self.recording is not None:
                self.recording.add(snap)
            wait = 0.0
            if time.monotonic() - start >= budget_s:
                break
        if time.monotonic() - self._last_flush >= self.settings.flush_interval_s:
            self.flush()
        return Advance(self.latest, self.seq, self.latest_wall, steps, tuple(samples), self._finished(),
                       max(wait, 0.0))

    # ---- persistence (worker thread) ----
    def _timeseries(self) -> dict[str, Any] | None:
        if self.loop is None or self.latest is None:
            return None
        data = dict(self.loop.timeseries())
        data.setdefault("scenario", self.scenario.to_json())
        return data

    def flush(self, metrics: dict[str, Any] | None = None) -> None:
        """Write the time series so far, the latest values and the recording's buffer to disk."""
        self._last_flush = time.monotonic()
        data = self._timeseries()
        if data is not None:
            write_npz_atomic(self.files.timeseries, data)
        if self.recording is not None:
            self.recording.flush()
        latest = None if self.latest is None else scalar_values(self.latest)
        self.repo.save_progress(self.run_id, latest, metrics)

    def finalize(self) -> dict[str, Any] | None:
        """Last flush; metrics of the run so far (``None`` entries where a window was not reached)."""
        metrics: dict[str, Any] | None = None
        if self.loop is not None and self.latest is not None:
            try:
                metrics = json_safe(dict(self.loop.metrics()))
            except Exception:
                log.exception("run %s: metrics failed", self.run_id)
        if metrics is not None:
            write_json_atomic(self.files.metrics, metrics)
        try:
            self.flush(metrics)
        finally:
            if self.recording is not None:
                self.recording.close()
            close = getattr(self.loop, "close", None)
            if callable(close):
                close()
        return metrics
