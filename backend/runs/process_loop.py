"""A run's closed loop in its own process, so that no run holds the server's interpreter.

With the loops in the server's threads, two runs at speed ``max`` keep the interpreter's lock (GIL)
busy, and every websocket send of the event loop (each one releases and retakes it) waits for it:
the frames of the other clients come late.  :class:`ProcessLoop` runs ``twin.runs.loop.ClosedLoop``
in a child process and answers the calls of the ``twin.runs.interface.Loop`` protocol:
each ``step()`` is one round trip over a pipe that returns the sample's snapshot.  The child appends
the run's time series itself (:meth:`ProcessLoop.append_series`, ``twin.runs.series_store``), so
flushes do not copy it between processes.  Runs at speed ``max`` get a lower CPU priority (``nice``): the server and the
runs paced in real time come first.

Children are forked from a fork server (``multiprocessing``'s "forkserver", safe with the server's
threads) that has the numerics imported already; each child loads the radiation model from the disk
cache (the server's warm-up has filled it) and builds its loop.  A child dies with the server
(``PR_SET_PDEATHSIG``); an exception in the child comes back as the same exception type when it
can be pickled, else as ``RuntimeError`` with its text.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import threading
from collections.abc import Callable
from concurrent.futures import Future
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanCancelled
from twin.events import RunEvent
from twin.scenario import FaultSpec, OscillationSpec, Reference, Scenario

log = logging.getLogger(__name__)

PRELOAD = ["numpy", "scipy.linalg", "casadi", "twin.runs.loop", "twin.control.replan", "twin.estimation.ekf",
           "twin.radiation.model", "twin.furnace.simulated.furnace"]
_CONTEXT: Any = None


def _context() -> Any:
    global _CONTEXT
    if _CONTEXT is None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        _CONTEXT = ctx
    return _CONTEXT


def _settle(fut: Future[float], ok: bool, value: Any) -> None:
    if ok:
        fut.set_result(value)
    else:
        fut.set_exception(value)


class LoopProcessError(RuntimeError):
    """The child failed in a way that cannot be re-raised as its own exception."""


def _die_with_parent() -> None:
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _portable(exc: BaseException) -> BaseException:
    """The exception as the parent will see it: itself if it survives pickling, else a RuntimeError."""
    import pickle

    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        kind = ValueError if isinstance(exc, ValueError) else LoopProcessError
        return kind(f"{type(exc).__name__}: {exc}")


def _serve(conn: Connection, cfg_json: str, scenario_json: str, niceness: int,
           limits: tuple[float, float]) -> None:  # pragma: no cover - child
    """The child: build the loop (its plans within ``limits`` = (max_wall_s, max_memory_mb)), then answer
    (method, args) messages until "close"."""
    _die_with_parent()
    if niceness:
        os.nice(niceness)
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)  # small matrices: BLAS threads would only contend (tests/conftest.py)
    except Exception:
        pass
    from twin.radiation import radiation_model
    from twin.runs.loop import ClosedLoop
    from twin.runs.record import save_arrays

    try:
        cfg = FurnaceConfig.model_validate_json(cfg_json)
        scenario = Scenario.model_validate_json(scenario_json)
        loop = ClosedLoop(cfg, scenario, radiation_model(cfg), background=True, budget=PlanBudget(*limits))
    except BaseException as exc:
        conn.send(("error", _portable(exc)))
        return
    conn.send(("ok", {"tc_positions": loop.tc_positions, "done": loop.done}))
    changes: dict[int, Future[float]] = {}  # changes still being planned (twin.runs.replanning), by id

    def outcome(fut: Future[float]) -> tuple[bool, Any]:
        exc = fut.exception()
        return (True, fut.result()) if exc is None else (False, _portable(exc))

    def settled() -> dict[int, tuple[bool, Any]]:
        done = {k: outcome(f) for k, f in changes.items() if f.done()}
        for k in done:
            del changes[k]
        return done

    while True:
        try:
            method, args = conn.recv()
        except EOFError:
            break
        try:
            if method == "close":
                loop.close()
                conn.send(("ok", None))
                break
            if method == "step":
                snap = loop.step()
                result: Any = (snap, loop.done, settled(), loop.replanning)
            elif method in ("set_reference", "set_oscillation"):
                fut = loop.set_reference(*args) if method == "set_reference" else loop.set_oscillation(*args)
                if not isinstance(fut, Future):
                    result = ("done", (True, None))
                elif fut.done():
                    result = ("done", outcome(fut))
                else:
                    key = id(fut)
                    changes[key] = fut
                    result = ("later", key)
            elif method == "replanning":
                result = loop.replanning
            elif method == "save_timeseries":
                save_arrays(args[0], loop.timeseries(), compress=False)
                result = None
            else:
                calls: dict[str, Callable[..., Any]] = {
                    "add_event": loop.add_event, "append_series": loop.append_series, "set_faults": loop.set_faults,
                    "faults_in_force": loop.faults_in_force, "timeseries": loop.timeseries, "metrics": loop.metrics,
                    "ending": loop.ending}
                if method not in calls:
                    raise ValueError(f"a run's loop has no call {method!r}")
                result = calls[method](*args)
            conn.send(("ok", result))
        except BaseException as exc:
            conn.send(("error", _portable(exc)))


class ProcessLoop:
    """``ClosedLoop(cfg, scenario)`` in a child process (module docstring); a ``twin.runs.interface.Loop``."""

    def __init__(self, cfg: FurnaceConfig, scenario: Scenario, *, budget: PlanBudget | None = None,
                 niceness: int = 0) -> None:
        budget = budget or PlanBudget()
        ctx = _context()
        here, there = ctx.Pipe()
        self._call_lock = threading.RLock()
        self._proc = ctx.Process(target=_serve, args=(there, cfg.model_dump_json(), scenario.model_dump_json(),
                                                      niceness, (budget.max_wall_s, budget.max_memory_mb)),
                                 name="furnace-run", daemon=True)
        self._proc.start()
        there.close()
        self._conn: Connection = here
        self._closed = False
        try:
            while not self._conn.poll(0.1):  # the child builds its loop (the first plan: seconds)
                if budget.cancelled:  # Stop while starting: the child's plan is abandoned with it
                    raise PlanCancelled("stopped while the run's first plan was being made")
                if not self._proc.is_alive() and not self._conn.poll(0):
                    break
            info = self._reply()
        except BaseException:
            self._kill()
            raise
        self.tc_positions = info["tc_positions"]
        self._done = bool(info["done"])
        self._changes: dict[int, Future[float]] = {}  # the child's changes still being planned
        self._replanning = False
        self.scenario, self.t_s = scenario, cfg.sampling.t_s

    def _reply(self) -> Any:
        try:
            kind, value = self._conn.recv()
        except EOFError:
            raise LoopProcessError(f"the run's process ended (exit status {self._proc.exitcode})") from None
        if kind == "error":
            raise value
        return value

    def _call(self, method: str, *args: Any) -> Any:
        """One round trip; one at a time (the run's thread steps, a route's thread may read the series)."""
        with self._call_lock:
            if self._closed:
                raise LoopProcessError("the run's process is closed")
            self._conn.send((method, args))
            return self._reply()

    # ---- twin.runs.interface.Loop ----
    @property
    def done(self) -> bool:
        return self._done

    @property
    def paced_by_furnace(self) -> bool:
        """A simulated furnace has no clock of its own: the run worker paces the run by its speed."""
        return False

    @property
    def replanning(self) -> bool:
        """A re-plan is being solved in the child (at speed max the run worker waits for it); asks the child
        only while the last answer (of a step or a change) said so."""
        if self._replanning:
            self._replanning = bool(self._call("replanning"))
        return self._replanning

    def step(self) -> Any:
        snap, self._done, settled, self._replanning = self._call("step")
        for key, (ok, value) in settled.items():  # changes whose plan came into force (or failed)
            fut = self._changes.pop(key, None)
            if fut is not None:
                _settle(fut, ok, value)
        return snap

    def _change(self, method: str, arg: Any) -> Future[float]:
        """The child's future of a change as a future here: settled with the step that installs it."""
        kind, value = self._call(method, arg)
        fut: Future[float] = Future()
        if kind == "later":
            self._changes[value] = fut
            self._replanning = True
        else:
            _settle(fut, *value)
        return fut

    def set_reference(self, ref: Reference) -> Future[float]:
        return self._change("set_reference", ref)

    def set_oscillation(self, spec: OscillationSpec) -> Future[float]:
        return self._change("set_oscillation", spec)

    def set_faults(self, faults: list[FaultSpec]) -> None:
        self._call("set_faults", faults)

    def faults_in_force(self) -> list[FaultSpec]:
        got: list[FaultSpec] = self._call("faults_in_force")
        return got

    def timeseries(self) -> dict[str, Any]:
        got: dict[str, Any] = self._call("timeseries")
        return got

    def save_timeseries(self, path: Path) -> None:
        """Write the time series (``timeseries.npz`` layout) to ``path`` from the child, atomically."""
        self._call("save_timeseries", str(path))

    def append_series(self, folder: Path) -> None:
        """Append the samples since the last call to the run's series parts in ``folder``
        (``twin.runs.series_store``), from the child."""
        self._call("append_series", Path(folder))

    def add_event(self, event: RunEvent) -> None:
        """The server's own events (the start, the changes' outcomes, saturated groups, the end) go into the
        series the child appends."""
        try:
            self._call("add_event", event)
        except LoopProcessError:  # the child is gone: the worker's own list still has the event
            log.warning("event not recorded, the run's process has ended: %s", event.text)

    def ending(self, end: str, error: str | None = None) -> tuple[str, str | None]:
        """The run's status and reason as the child's loop knows them (a run that finished blind: degraded)."""
        status, reason = self._call("ending", end, error)
        return str(status), reason

    def metrics(self) -> dict[str, Any]:
        got: dict[str, Any] = self._call("metrics")
        return got

    def close(self) -> None:
        with self._call_lock:  # no other round trip starts on the closed pipe
            if self._closed:
                return
            try:
                self._call("close")
            except Exception:
                log.warning("the run's process did not close cleanly", exc_info=True)
            self._closed = True
            self._conn.close()
        self._proc.join(timeout=10)
        if self._proc.is_alive():
            self._kill()
        for fut in self._changes.values():  # the run ended before these were planned
            fut.set_exception(PlanCancelled("the run ended before the change was planned"))
        self._changes.clear()

    def _kill(self) -> None:
        self._closed = True
        if self._proc.is_alive():
            self._proc.kill()
        self._proc.join(timeout=10)
