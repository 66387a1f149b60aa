"""A run's live changes: queued from any thread, handed to its loop in the run's thread, settled once.

:class:`ChangeQueue` takes reference / oscillation / fault changes: :meth:`ChangeQueue.submit` queues one (any
thread) and returns a future of its outcome; the run's host hands the queue to its loop between two samples
(:meth:`ChangeQueue.hand_over`, the run's thread).  A loop that re-plans in the background returns a
future per change (``twin.runs.replanning``): the change is ``pending`` until its plan is in force
(``applied``, with the run time), and ends ``superseded`` (a later change of the same kind won),
``failed`` / ``rejected`` (nothing of it applied: :class:`ChangeRejected`) or ``cancelled`` (the run ended
first: :class:`ChangeCancelled`); faults apply at once.  Each outcome goes to the host's ``settled`` (the
server writes the change's database row) and is reported through its ``event`` as one of the run's events.
The queue keeps what is in force (:attr:`ChangeQueue.reference`, ``oscillation``, ``faults``).
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
from typing import Any

from twin.control.budget import PlanCancelled
from twin.runs.interface import Loop
from twin.runs.replanning import Superseded
from twin.scenario import FaultSpec, OscillationSpec, Reference, Scenario, describe

log = logging.getLogger(__name__)

#: the host's record of a change's outcome: (change id, status, run time in force or None, message or None)
Settled = Callable[[int, str, float | None, str | None], None]
#: the host's event of the run: (run time or None for "at the next sample", text, level)
Event = Callable[[float | None, str, str], None]


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


class ChangeQueue:
    """The live changes of one run and what is in force (module docstring)."""

    def __init__(self, run_id: str, scenario: Scenario, settled: Settled, event: Event) -> None:
        self.run_id = run_id
        self._settled, self._event = settled, event
        #: in force: the scenario's, then each applied change (faults' ``at`` in run time)
        self.reference: Reference = scenario.reference
        self.oscillation: OscillationSpec = scenario.oscillation
        self.faults: list[FaultSpec] = list(scenario.faults)
        self._changes: deque[_Change] = deque()
        self._changes_lock = threading.Lock()

    def submit(self, kind: str, value: Any, change_id: int,
               notes: tuple[str, ...] = ()) -> concurrent.futures.Future[dict[str, Any]]:
        """Queue a change (any thread); the future gives its outcome."""
        fut: concurrent.futures.Future[dict[str, Any]] = concurrent.futures.Future()
        with self._changes_lock:
            self._changes.append(_Change(kind, value, change_id, fut, notes))
        return fut

    def hand_over(self, loop: Loop, t: float) -> bool:
        """Hand the queued changes to the loop (the run's thread), ``t`` the first sample that could use them;
        True if one was applied at once (a loop without futures)."""
        applied = False
        while True:
            with self._changes_lock:
                if not self._changes:
                    return applied
                ch = self._changes.popleft()
            t0 = time.monotonic()
            try:
                if ch.kind == "reference":
                    fut = loop.set_reference(ch.value)
                elif ch.kind == "faults":
                    loop.set_faults(ch.value)
                    fut = None  # in the furnace from the next sample on
                else:
                    fut = loop.set_oscillation(ch.value)
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
            self._settled(ch.change_id, "applied", t, None)
            for note in ch.notes:
                self._event(t, f"feasibility: {note}", "warn")
            ch.future.set_result({"status": "applied", "applied_t": t, "replan_s": replan_s})
            return
        what = f"{ch.kind} change to {describe(ch.value)}"
        if isinstance(exc, Superseded):
            self._settled(ch.change_id, "superseded", None, str(exc))
            self._event(None, f"{what} superseded: {exc}", "info")
            ch.future.set_result({"status": "superseded", "applied_t": None, "message": str(exc)})
        elif isinstance(exc, PlanCancelled):
            self._settled(ch.change_id, "cancelled", None, str(exc))
            self._event(None, f"{what} cancelled: {exc}", "warn")
            ch.future.set_exception(ChangeCancelled(str(exc)))
        elif isinstance(exc, ValueError):  # unreachable, or beyond this server's plan limits
            self._settled(ch.change_id, "rejected", t, str(exc))
            self._event(t, f"{what} refused: {exc}", "warn")
            ch.future.set_exception(ChangeRejected(str(exc)))
        else:  # the solve failed: the run goes on with its old plan
            log.warning("run %s: %s change %d failed: %r", self.run_id, ch.kind, ch.change_id, exc)
            message = f"re-planning failed, the run goes on as before: {exc}"
            self._settled(ch.change_id, "failed", None, message)
            self._event(t, f"{what}: {message}", "error")
            ch.future.set_exception(ChangeRejected(message))

    def cancel_all(self, reason: str) -> None:
        """The run ended: every change still queued is cancelled."""
        with self._changes_lock:
            pending, self._changes = list(self._changes), deque()
        for ch in pending:
            self._settled(ch.change_id, "cancelled", None, reason)
            self._event(None, f"{ch.kind} change to {describe(ch.value)} cancelled: {reason}", "warn")
            ch.future.set_exception(ChangeCancelled(reason))
