"""A run's live changes: queued from any thread, handed to its loop in the worker thread, settled once.

:class:`RunChanges` is the part of :class:`backend.runs.worker.RunWorker` (which mixes it in) that takes
reference / oscillation / fault changes: :meth:`RunChanges.submit_change` queues one (any thread) and
returns a future of its outcome; the worker hands the queue to its loop between two samples
(:meth:`RunChanges._apply_changes`, worker thread).  A loop that re-plans in the background returns a
future per change (``twin.runs.replanning``): the change is ``pending`` until its plan is in force
(``applied``, with the run time), and ends ``superseded`` (a later change of the same kind won),
``failed`` / ``rejected`` (nothing of it applied: :class:`ChangeRejected`) or ``cancelled`` (the run ended
first: :class:`ChangeCancelled`); faults apply at once.  Each outcome is written to the change's database
row and reported as one of the run's events.
"""

from __future__ import annotations

import concurrent.futures
import functools
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from backend.storage.repository import RunRepository
from backend.streaming.frames import SnapshotLike
from twin.config import FurnaceConfig
from twin.control.budget import PlanCancelled
from twin.runs.replanning import Superseded
from twin.scenario import FaultSpec, OscillationSpec, Reference, describe

if TYPE_CHECKING:
    from backend.runs.worker import LoopLike

log = logging.getLogger("backend.runs.worker")  # the worker's log, as before the split


class ChangeRejected(ValueError):
    """The loop refused a change, or could not plan it (an unreachable reference, a plan beyond the
    server's time or memory, a failed solve); nothing of it was applied."""


class ChangeCancelled(RuntimeError):
    """The run ended before the change was planned; nothing of it was applied."""


@dataclass
class _Change:
    kind: str  # "reference" | "oscillation" | "faults"
    value: Any
    change_id: int
    future: concurrent.futures.Future[dict[str, Any]]
    notes: tuple[str, ...] = ()  # feasibility warnings, reported as events when the change applies


class RunChanges:
    """The change queue of a run's worker (``backend.runs.worker.RunWorker`` mixes it in)."""

    run_id: str
    cfg: FurnaceConfig
    repo: RunRepository
    loop: LoopLike | None
    latest: SnapshotLike | None
    reference: Reference
    oscillation: OscillationSpec
    faults: list[FaultSpec]
    _changes: deque[_Change]
    _changes_lock: threading.Lock
    _add_later: Callable[[float | None, str, str], None]  # RunWorker's: an event added at its next step

    def submit_change(self, kind: str, value: Any, change_id: int,
                      notes: tuple[str, ...] = ()) -> concurrent.futures.Future[dict[str, Any]]:
        fut: concurrent.futures.Future[dict[str, Any]] = concurrent.futures.Future()
        with self._changes_lock:
            self._changes.append(_Change(kind, value, change_id, fut, notes))
        return fut

    def _apply_changes(self) -> bool:
        """Hand the queued changes to the loop; True if one was applied at once (a loop without futures)."""
        assert self.loop is not None
        applied = False
        while True:
            with self._changes_lock:
                if not self._changes:
                    return applied
                ch = self._changes.popleft()
            # the first sample that could use the change
            t = float(self.latest.t) + self.cfg.sampling.t_s if self.latest is not None else 0.0
            t0 = time.monotonic()
            try:
                if ch.kind == "reference":
                    fut = self.loop.set_reference(ch.value)
                elif ch.kind == "faults":
                    set_faults = getattr(self.loop, "set_faults", None)
                    if not callable(set_faults):
                        raise ValueError("faults can be injected only into a simulated furnace")
                    set_faults(ch.value)
                    fut = None  # in the furnace from the next sample on
                else:
                    fut = self.loop.set_oscillation(ch.value)
            except Exception as exc:  # refused or failed before anything changed: the run goes on as it was
                self._settle(ch, t0, exc=exc, t=t)
                continue
            if fut is None:  # a loop that applies at once
                self._settle(ch, t0, t=t)
                applied = True
            else:
                fut.add_done_callback(functools.partial(self._settled_future, ch, t0))
        return applied

    def _settled_future(self, ch: _Change, t0: float, fut: Future[float]) -> None:
        exc = fut.exception()
        self._settle(ch, t0, exc=exc, t=None if exc is not None else fut.result())

    def _settle(self, ch: _Change, t0: float, *, exc: BaseException | None = None, t: float | None = None) -> None:
        """Record the outcome of a change and answer whoever waits for it."""
        if ch.future.done():
            return
        if exc is None:
            if ch.kind == "reference":
                self.reference = ch.value
            elif ch.kind == "faults":
                self.faults = [f.model_copy(update={"at": f.at + (t or 0.0)}) for f in ch.value]
            else:
                self.oscillation = ch.value
            replan_s = time.monotonic() - t0
            log.info("run %s: %s change %d in force from t=%.1f s (%.2f s after it was handed over)",
                     self.run_id, ch.kind, ch.change_id, t, replan_s)
            self.repo.finish_change(ch.change_id, "applied", t, None)
            for note in ch.notes:
                self._add_later(t, f"feasibility: {note}", "warn")
            ch.future.set_result({"status": "applied", "applied_t": t, "replan_s": replan_s})
            return
        what = f"{ch.kind} change to {describe(ch.value)}"
        if isinstance(exc, Superseded):
            self.repo.finish_change(ch.change_id, "superseded", None, str(exc))
            self._add_later(None, f"{what} superseded: {exc}", "info")
            ch.future.set_result({"status": "superseded", "applied_t": None, "message": str(exc)})
        elif isinstance(exc, PlanCancelled):
            self.repo.finish_change(ch.change_id, "cancelled", None, str(exc))
            self._add_later(None, f"{what} cancelled: {exc}", "warn")
            ch.future.set_exception(ChangeCancelled(str(exc)))
        elif isinstance(exc, ValueError):  # unreachable, or beyond this server's plan limits
            self.repo.finish_change(ch.change_id, "rejected", t, str(exc))
            self._add_later(t, f"{what} refused: {exc}", "warn")
            ch.future.set_exception(ChangeRejected(str(exc)))
        else:  # the solve failed: the run goes on with its old plan
            log.warning("run %s: %s change %d failed: %r", self.run_id, ch.kind, ch.change_id, exc)
            message = f"re-planning failed, the run goes on as before: {exc}"
            self.repo.finish_change(ch.change_id, "failed", None, message)
            self._add_later(t, f"{what}: {message}", "error")
            ch.future.set_exception(ChangeRejected(message))

    def cancel_changes(self, reason: str) -> None:
        with self._changes_lock:
            pending, self._changes = list(self._changes), deque()
        for ch in pending:
            self.repo.finish_change(ch.change_id, "cancelled", None, reason)
            self._add_later(None, f"{ch.kind} change to {describe(ch.value)} cancelled: {reason}", "warn")
            ch.future.set_exception(ChangeCancelled(reason))
