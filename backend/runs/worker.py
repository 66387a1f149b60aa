"""One run's closed loop, driven from its own worker thread.

:class:`RunWorker` owns the ``twin.runs.loop.ClosedLoop`` of a run and everything the run
writes: the ``.rrd`` recording, ``timeseries.npz``, ``metrics.json`` and its database
rows.  The run manager's async task calls :meth:`RunWorker.advance` in the run's thread;
each call steps the loop as far as the speed allows (real time x factor, or as fast as
possible) for at most a small wall-time budget and returns the latest snapshot.  A loop on a
real-time furnace (``paced_by_furnace``) is not paced here: its step waits, in this thread, for the
furnace's next sample, so the furnace's clock drives the run and the server's event loop never waits.
Reference / oscillation / fault changes are queued and handed to the loop between two samples, in
this thread, never on the event loop (``twin.runs.changes.ChangeQueue``, held by the worker).  A loop that
re-plans in the background returns a future per change (``twin.runs.replanning``): the change is
``pending`` until its plan is in force (``applied``, with the run time), and ends ``superseded`` (a later
change of the same kind won), ``failed`` / ``rejected`` (nothing of it applied) or ``cancelled`` (the run
ended first); faults apply at once.  Every plan of the run has a budget (``Settings.plan_max_s``,
``plan_max_mb``) and is cancelled by the run's stop event, also while the run is starting.

The worker keeps the run's events (``backend.runs.events``: the loop's and the server's), each added once
in the worker thread to its list, the loop's run record (``timeseries.npz``) and the recording.  The run's
fault events (faults injected, cleared, detected) are kept in ``faults.json`` beside the recording as well.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Any

from backend.core.settings import Settings
from backend.runs.events import RunEvents, end_event
from backend.runs.factory import LoopFactory
from backend.storage.data_dir import DataDir
from backend.storage.recording import RecordingSink
from backend.storage.repository import RunRepository
from backend.streaming.frames import SnapshotLike, events_of, scalar_values
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanCancelled
from twin.events import RunEvent, event_arrays
from twin.physics.fillet import Fillet
from twin.runs.changes import ChangeQueue
from twin.runs.folder import RunFolder
from twin.runs.interface import Loop
from twin.runs.outage import run_ending
from twin.runs.session import RunSession
from twin.scenario import FaultSpec, OscillationSpec, Reference, Scenario, describe

log = logging.getLogger(__name__)


#: the events of a run that faults.json keeps (twin.furnace.simulated.faults, twin.runs.loop)
FAULT_EVENT_PREFIXES = ("fault injected", "faults cleared", "fault detected")


class DiskFull(RuntimeError):
    """The data directory passed its quota, or the disk its free-space reserve, during the run."""


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


class RunWorker:
    """Steps one closed loop at the scenario's speed and persists what it produces."""

    def __init__(
        self,
        run_id: str,
        scenario: Scenario,
        cfg: FurnaceConfig,
        settings: Settings,
        repo: RunRepository,
        files: RunFolder,
        loop_factory: LoopFactory,
        *,
        disk: DataDir | None = None,
        notes: tuple[str, ...] = (),
        live_url: str | None = None,
    ) -> None:
        self.run_id = run_id
        self.disk = disk
        self.live_url = live_url  # a rerun viewer / proxy the recording also streams to
        self.scenario = scenario
        self.cfg = cfg
        self.settings = settings
        self.repo = repo
        self.files = files
        self._factory = loop_factory
        self.loop: Loop | None = None
        self.session: RunSession | None = None  #: the loop with the run's folder and recording (twin.runs.session)
        self.recording: RecordingSink | None = None
        self.speed: float | None = None if scenario.speed == "max" else float(scenario.speed)
        #: the live changes (``twin.runs.changes``): each outcome in the change's row and as an event
        self.changes = ChangeQueue(run_id, scenario, repo.finish_change, self._add_later)
        self.fault_events: list[dict[str, Any]] = []  #: the fault events so far
        self.latest: SnapshotLike | None = None
        self.ending: tuple[str, str | None] | None = None  # (status, status_reason) once finalised
        self.latest_wall = 0.0
        self.seq = 0
        self.stop_requested = threading.Event()
        self._origin_wall = 0.0
        self._origin_t = 0.0
        self._last_flush = 0.0
        self._events = RunEvents(tuple(g.name for g in cfg.lamps.groups), cfg.sampling.t_s)
        self.events = self._events.items  #: the run's events, oldest first (backend.runs.events)
        self.notes = notes  #: feasibility warnings of the scenario, reported as events when the run starts
        self.fillet = Fillet.of(cfg)  # for the frames' spread (backend.streaming.frames.frame_extra)

    # ---- what is in force (the scenario's, then each applied change) ----
    @property
    def reference(self) -> Reference:
        return self.changes.reference

    @property
    def oscillation(self) -> OscillationSpec:
        return self.changes.oscillation

    @property
    def faults(self) -> list[FaultSpec]:
        """The faults injected (``at`` in run time: the scenario's, then each applied PUT)."""
        return self.changes.faults

    # ---- events ----
    def add_event(self, t: float, text: str, level: str | None = None, *, in_record: bool = False) -> None:
        """A sentence of the run (worker thread): a ``said`` event (:meth:`add`)."""
        self.add(RunEvent.said(float(t), text, level), in_record=in_record)

    def add(self, event: RunEvent, *, in_record: bool = False) -> None:
        """One event of the run (worker thread): kept for the stream, the run record (``in_record``: the loop
        put it there already) and the recording."""
        self.events.append(event)
        if not in_record and self.loop is not None:
            self.loop.add_event(event)
        if self.recording is not None:
            self.recording.log_event(event.t, event.text, event.level)

    def _add_later(self, t: float | None, text: str, level: str) -> None:
        """An event from another thread (a change settled by the re-planning thread): added at the next step."""
        at = t if t is not None else (float(self.latest.t) if self.latest is not None else 0.0)
        self._events.later(RunEvent.said(float(at), text, level))

    def _add_queued(self) -> None:
        for e in self._events.queued():
            self.add(e)

    # ---- set-up (worker thread) ----
    def build(self) -> None:
        """Create the closed loop (this solves the first feedforward: seconds) and the recording."""
        self.files.folder.mkdir(parents=True, exist_ok=True)
        self.recording = RecordingSink(
            self.cfg, self.run_id, self.files.recording,
            tc_positions=self.cfg.tc_positions(self.scenario.tc4),
            image_interval=self.settings.recording_image_interval_s, live_url=self.live_url,
        )
        self.loop = self._factory(self.cfg, self.scenario, budget=self.budget())
        self.session = RunSession(self.loop, self.files, sinks=[self.recording])
        if self.stop_requested.is_set():  # stopped while the first plan was being made
            raise PlanCancelled("the run was stopped while it was starting")
        sc = self.scenario
        speed = "as fast as possible" if sc.speed == "max" else f"{float(sc.speed):g} x real time"
        self.add(RunEvent(0.0, "run_started", "info", {
            "reference": describe(sc.reference), "oscillation": describe(sc.oscillation),
            "duration": float(sc.duration), "speed": speed}))
        for note in self.notes:
            self.add(RunEvent(0.0, "feasibility", "warn", {"note": note}))
        self._rebase(0.0)
        self._last_flush = time.monotonic()

    def budget(self) -> PlanBudget:
        """The plans' budget: this server's limits, cancelled by the run's stop."""
        return PlanBudget.of(self.settings.plan_max_s, self.settings.plan_max_mb, self.stop_requested)

    def _rebase(self, t: float) -> None:
        """Real-time pacing restarts from now at simulated time ``t`` (after set-up or a re-plan)."""
        self._origin_wall = time.monotonic()
        self._origin_t = t

    # ---- stepping (worker thread) ----
    def _finished(self) -> bool:
        assert self.loop is not None
        if self.loop.done:
            return True
        return self.latest is not None and float(self.latest.t) >= self.scenario.duration - 1e-9

    def advance(self, budget_s: float) -> Advance:
        """Step while samples are due (speed) for at most ``budget_s`` wall seconds."""
        assert self.loop is not None and self.session is not None
        start = time.monotonic()
        steps = 0
        samples: list[tuple[SnapshotLike, int, float]] = []
        t_s = self.cfg.sampling.t_s
        wait = 0.0
        self._add_queued()
        while not self.stop_requested.is_set() and not self._finished():
            t_next = float(self.latest.t) + t_s if self.latest is not None else 0.0  # the first that could use it
            if self.changes.hand_over(self.loop, t_next):
                self._rebase(float(self.latest.t) if self.latest is not None else 0.0)
            if self.speed is None and self.loop.replanning:
                # at speed max simulated time waits for a re-plan (free here), so the plan is not stale
                # when it comes in and a change counts from the sample it was asked at; in real time
                # the furnace goes on under the old plan
                wait = 0.02
                break
            next_t = (float(self.latest.t) if self.latest is not None else 0.0) + t_s
            if self.speed is not None and not self.loop.paced_by_furnace:
                due = self._origin_wall + (next_t - self._origin_t) / self.speed
                wait = due - time.monotonic()
                if wait > 0:
                    break
            snap = self.session.step()  # into the run record and the recording
            self.latest, self.latest_wall = snap, time.time()
            self.seq += 1
            steps += 1
            samples.append((snap, self.seq, self.latest_wall))
            self._add_queued()
            for text in events_of(snap.events):  # the loop put them into its record with the sample
                self.add_event(float(snap.t), text, in_record=True)
                if text.startswith(FAULT_EVENT_PREFIXES):
                    self.fault_events.append({"t": float(snap.t), "text": text})
            error = float(snap.T_ref) - float(snap.T_mean_hat)  # behind the reference: > 0
            for event in self._events.saturation.update(float(snap.t), snap.u, error):
                self.add(event)
            wait = 0.0
            if time.monotonic() - start >= budget_s:
                break
        if time.monotonic() - self._last_flush >= self.settings.flush_interval_s:
            self.flush()
            problem = None if self.disk is None else self.disk.over()
            if problem is not None:
                raise DiskFull(f"{problem}: the run was stopped, its data so far kept")
        return Advance(self.latest, self.seq, self.latest_wall, steps, tuple(samples), self._finished(),
                       max(wait, 0.0))

    # ---- persistence (worker thread) ----
    def _timeseries(self) -> dict[str, Any] | None:
        if self.loop is None or self.latest is None:
            return None
        data = dict(self.loop.timeseries())
        data.setdefault("scenario", self.scenario.to_json())
        return data

    def live_series(self) -> dict[str, Any] | None:
        """The time series so far (the ``timeseries.npz`` layout), fresher than the last flush, with the events
        numbered as the frames number them (this worker's list); any thread.  ``None`` once the loop has
        closed (a loop in its own process: the run's files have the series then)."""
        try:
            data = self._timeseries()
        except RuntimeError as exc:  # backend.runs.process_loop.LoopProcessError: the run ended meanwhile
            log.info("run %s: live series unavailable (%s); read from its files", self.run_id, exc)
            return None
        if data is not None:
            data.update(event_arrays(list(self.events)))
        return data

    def flush(self, metrics: dict[str, Any] | None = None) -> None:
        """Append the new samples to the time series (``twin.runs.series_store``), store the latest values and
        push the recording's buffer to disk."""
        self._last_flush = time.monotonic()
        if self.session is not None:  # a loop in its own process appends there
            self.session.flush()
        elif self.recording is not None:
            self.recording.flush()
        if self.fault_events or self.faults:
            self.files.write_faults(self.faults, self.fault_events)
        latest = None if self.latest is None else scalar_values(self.latest)
        self.repo.save_progress(self.run_id, latest, metrics)

    def _ending(self, status: str, error: str | None) -> tuple[str, str | None]:
        """The run's status and its reason (``twin.runs.outage.run_ending``: a run that finished blind ended
        ``degraded``), from the loop that knows when it ran blind."""
        if self.session is not None:
            return self.session.end(status, error)
        return run_ending(status, error, None, float(self.latest.t) if self.latest is not None else 0.0)

    def _remember(self, metrics: dict[str, Any]) -> None:
        """A finished run's calibration goes to the furnace's memory (twin.control.calibration_memory)."""
        calibration = metrics.get("calibration")
        if not isinstance(calibration, dict) or metrics.get("status") != "finished":
            return
        from twin.control.calibration_memory import CalibrationMemory

        try:
            memory = CalibrationMemory.of(self.settings.data_dir, self.cfg, self.scenario)
            memory.learn(self.run_id, calibration, self.cfg)
        except OSError:
            log.exception("run %s: the calibration memory could not be written", self.run_id)

    def finalize(self, status: str | None = None, error: str | None = None) -> dict[str, Any] | None:
        """The run's end as an event (``status``: finished, stopped, ...), the last flush; metrics of the run so
        far (``None`` entries where a window was not reached) with ``status`` and ``status_reason``
        (:attr:`ending`: a run that was blind at its end ended ``degraded``)."""
        self._add_queued()
        if status is not None:
            self.ending = self._ending(status, error)
            final, reason = self.ending
            t_end = float(self.latest.t) if self.latest is not None else 0.0
            for spell in self._events.saturation.flush(t_end):  # spells still open at the end
                self.add(spell)
            self.add(end_event(final, t_end, reason if final == "degraded" else error))
        metrics = self.session.metrics() if self.session is not None else None
        if metrics is not None:
            if self.ending is not None:
                metrics.update(status=self.ending[0], status_reason=self.ending[1])
            self.files.write_metrics(metrics)
            self._remember(metrics)
        try:
            self.flush(metrics)
        finally:  # timeseries.npz of product.md from the parts, the recording and the loop closed
            if self.session is not None:
                self.session.close()
            elif self.recording is not None:
                self.recording.close()
        return metrics
