"""Live changes of a running loop: one re-plan at a time, the latest change wins, nothing applied early.

A change (new reference, new oscillation) needs a new plan (feedforward, gains, model); the loop
(:class:`twin.runs.loop.ClosedLoop`) keeps running on its old plan until the new one is ready, then
switches reference, motion and plan together at one sample.  :class:`Replanner` schedules those jobs:

* every change gets a :class:`concurrent.futures.Future` that resolves with the run time from which it
  counts (``applied``; the loop says which: a reference's own start, the motion's switch), or fails:
  :class:`Superseded` when a later change of the same kind replaced it before it was planned,
  :class:`twin.control.budget.PlanCancelled` when the run stopped, or
  the planning error (``PlanTooLarge``, ``FeedforwardError``, ...): then nothing of it was applied;
* a new change cancels the job in progress (its :class:`twin.control.budget.PlanBudget` token: it stops
  within milliseconds) and plans the latest wanted state instead, so a burst of changes costs one plan;
  the earlier changes of other kinds ride along in it;
* without a background thread (CLI, tests) the job runs at once and is installed before ``request``
  returns.

Example
-------
>>> r = Replanner(background=False)
>>> installed = []
>>> fut = r.request("reference", lambda budget: "plan A", install=lambda plan, changes: installed.append(plan) or 1.5)
>>> fut.result(), installed
(1.5, ['plan A'])
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

from twin.control.budget import PlanBudget, PlanCancelled

log = logging.getLogger(__name__)

Job = Callable[[PlanBudget], Any]  # plans with the given budget (it raises PlanCancelled when told to stop)
#: installs a plan at a sample boundary; returns the run time from which each kind's change counts
Install = Callable[[Any, list[str]], "float | dict[str, float]"]
OnFail = Callable[[BaseException, list[str]], None]  # a job failed or was cancelled: nothing was installed


class Superseded(RuntimeError):
    """A later change of the same kind replaced this one before it was planned; it was never applied."""


@dataclass
class _Ticket:
    kind: str
    future: Future[float] = field(default_factory=Future)


@dataclass
class _Running:
    future: Future[Any]
    budget: PlanBudget
    tickets: list[_Ticket]
    install: Install
    on_fail: OnFail | None


class Replanner:
    """Coalesced, cancellable re-planning jobs of one loop (module docstring).

    Parameters
    ----------
    background : plan in a worker thread (the backend) instead of inline.
    budget : the run's budget; every job gets a :meth:`PlanBudget.child` of it (its own token, cancelled
        with the run's too).
    """

    def __init__(self, background: bool, budget: PlanBudget | None = None) -> None:
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="replan") if background else None
        self._budget = budget or PlanBudget()
        self._running: _Running | None = None

    @property
    def busy(self) -> bool:
        """A job is being planned or waits to be installed at the next :meth:`poll`."""
        return self._running is not None

    @property
    def solving(self) -> bool:
        """A job is being planned."""
        r = self._running
        return r is not None and not r.future.done()

    def request(self, kind: str, job: Job, install: Install, on_fail: OnFail | None = None) -> Future[float]:
        """Plan ``job`` for a change of ``kind``; the job in progress is cancelled and its other changes ride
        along (their state is part of the new job); same-kind ones are superseded.  ``install(plan, kinds)``
        runs at the sample boundary where the plan takes over (:meth:`poll`), ``on_fail(exc, kinds)`` when
        the job fails (not when a newer request cancelled it)."""
        ticket = _Ticket(kind)
        carried: list[_Ticket] = []
        if self._running is not None:
            old, self._running = self._running, None
            old.budget.cancel.cancel()
            for t in old.tickets:
                if t.kind == kind:
                    t.future.set_exception(Superseded(f"superseded by a later {kind} change"))
                else:
                    carried.append(t)
        tickets = [*carried, ticket]
        budget = self._budget.child()
        if self._executor is None:
            self._finish(_Running(_done(job, budget), budget, tickets, install, on_fail))
            return ticket.future
        self._running = _Running(self._executor.submit(job, budget), budget, tickets, install, on_fail)
        return ticket.future

    def poll(self) -> None:
        """At a sample boundary: install a finished job (or report its failure); call it in the loop's step."""
        r = self._running
        if r is None or not r.future.done():
            return
        self._running = None
        self._finish(r)

    def _finish(self, r: _Running) -> None:
        kinds = sorted({t.kind for t in r.tickets})
        try:
            plan = r.future.result()
        except BaseException as exc:  # nothing of these changes is in force
            for t in r.tickets:
                if not t.future.done():
                    t.future.set_exception(exc)
            if not isinstance(exc, PlanCancelled):
                log.warning("re-planning (%s) failed: %s", ", ".join(kinds), exc)
            if r.on_fail is not None:
                r.on_fail(exc, kinds)
            return
        applied = r.install(plan, kinds)
        for t in r.tickets:
            if not t.future.done():
                t.future.set_result(applied[t.kind] if isinstance(applied, dict) else applied)

    def close(self, reason: str = "the run ended") -> None:
        """Cancel the job in progress; its changes fail with :class:`PlanCancelled`."""
        r, self._running = self._running, None
        if r is not None:
            r.budget.cancel.cancel()
            for t in r.tickets:
                if not t.future.done():
                    t.future.set_exception(PlanCancelled(f"not applied: {reason}"))
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)


def _done(job: Job, budget: PlanBudget) -> Future[Any]:
    """Run ``job`` now; its result or exception in a finished future."""
    fut: Future[Any] = Future()
    try:
        fut.set_result(job(budget))
    except BaseException as exc:
        fut.set_exception(exc)
    return fut
