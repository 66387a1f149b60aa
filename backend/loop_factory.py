"""The loop factory of the server: real ``twin.runs.loop.ClosedLoop`` runs sharing one radiation model.

The radiation model (exchange factors, ray-traced once per furnace and cached on disk) is loaded in a
background thread as soon as the server starts (:meth:`DefaultLoopFactory.start_warm_up`); until it is
ready the server answers everything at once, ``GET /api/health`` reports ``"radiation": "computing"``
with the progress, and new runs wait in the status ``queued`` (backend.run_manager).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, replace
from typing import Any, Literal

from backend.run_worker import LoopLike
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanCancelled
from twin.scenario import Reference, Scenario

log = logging.getLogger(__name__)

RadiationState = Literal["computing", "ready", "failed"]


@dataclass(frozen=True)
class WarmUpStatus:
    """Where the radiation model of one furnace stands."""

    state: RadiationState
    stage: str  # "waiting", "loading the cache", "ray tracing", "building the model", "ready", "failed"
    done: int = 0  # positions ray-traced (of ``total``); total once loaded from the cache
    total: int = 0
    started: float = 0.0  # time.monotonic() at the start
    finished: float | None = None
    error: str | None = None

    @property
    def fraction(self) -> float:
        if self.state == "ready":
            return 1.0
        return self.done / self.total if self.total else 0.0

    @property
    def elapsed_s(self) -> float:
        return (self.finished if self.finished is not None else time.monotonic()) - self.started


#: CPU priority of a run at speed max (os.nice): the server and the runs paced in real time come first
MAX_SPEED_NICENESS = 5


class DefaultLoopFactory:
    """Builds the server's runs: each ``twin.runs.loop.ClosedLoop`` in its own process
    (:class:`backend.process_loop.ProcessLoop`), or in the server's process with ``processes=False``
    (sharing the radiation model loaded here)."""

    def __init__(self, *, processes: bool = True) -> None:
        self.processes = processes
        self._lock = threading.Lock()
        self._radiation: dict[str, Any] = {}
        self._T_range: dict[str, tuple[float, float]] = {}
        self._status: dict[str, WarmUpStatus] = {}
        self._ready: dict[str, threading.Event] = {}
        self._status_lock = threading.Lock()

    # ---- warm-up ----
    def _event(self, key: str) -> threading.Event:
        with self._status_lock:
            return self._ready.setdefault(key, threading.Event())

    def _set(self, key: str, **changes: Any) -> None:
        with self._status_lock:
            self._status[key] = replace(self._status[key], **changes)

    def start_warm_up(self, cfg: FurnaceConfig) -> None:
        """Load (or ray-trace) the radiation model of ``cfg`` in a daemon thread; idempotent."""
        key = cfg.digest()
        with self._status_lock:
            if key in self._status:
                return
            self._status[key] = WarmUpStatus("computing", "waiting", started=time.monotonic())
        threading.Thread(target=self._warm_up, args=(cfg,), name="radiation-warm-up", daemon=True).start()

    def _warm_up(self, cfg: FurnaceConfig) -> None:
        key = cfg.digest()
        try:
            self.radiation(cfg)
            self._set(key, stage="building the model")
            self.reachable_range(cfg)
            self._set(key, state="ready", stage="ready", finished=time.monotonic())
            log.info("radiation model ready (%.1f s)", self._status[key].elapsed_s)
        except Exception as exc:
            log.exception("loading the radiation model failed; runs will retry")
            self._set(key, state="failed", stage="failed", error=f"{type(exc).__name__}: {exc}",
                      finished=time.monotonic())
        finally:
            self._event(key).set()

    def warm_up_status(self, cfg: FurnaceConfig) -> WarmUpStatus:
        """The radiation model's state: ``ready`` once loaded (also when it was loaded without a warm-up)."""
        key = cfg.digest()
        with self._status_lock:
            st = self._status.get(key)
        if st is None:
            return WarmUpStatus("ready" if key in self._radiation else "computing",
                                "ready" if key in self._radiation else "waiting")
        return st

    def ready(self, cfg: FurnaceConfig) -> bool:
        """True when a run can be built without waiting for the radiation model."""
        return cfg.digest() in self._radiation and self.warm_up_status(cfg).state != "computing"

    def wait_ready(self, cfg: FurnaceConfig, timeout: float) -> bool:
        """Block until the warm-up of ``cfg`` ended (ready or failed) or ``timeout`` s passed."""
        if self.ready(cfg):
            return True
        key = cfg.digest()
        with self._status_lock:
            started = key in self._status
        if not started:
            self.start_warm_up(cfg)
        return self._event(key).wait(timeout)

    # ---- the model ----
    def radiation(self, cfg: FurnaceConfig, budget: PlanBudget | None = None) -> Any:
        """The furnace's radiation model, loaded (or ray-traced) once; a run waiting for another caller's
        computation stops waiting when its ``budget`` is cancelled (Stop while starting)."""
        from twin.radiation import radiation_model  # type: ignore[attr-defined]  # lands with the radiation part

        key = cfg.digest()
        while not self._lock.acquire(timeout=0.1):
            if budget is not None and budget.cancelled:
                raise PlanCancelled("stopped while the radiation model was being computed")
        try:
            if key not in self._radiation:
                if key in self._status:
                    self._set(key, stage="loading the cache")

                def traced(done: int, total: int) -> None:
                    if key in self._status:
                        self._set(key, stage="ray tracing", done=done, total=total)

                self._radiation[key] = radiation_model(cfg, on_position=traced)
            return self._radiation[key]
        finally:
            self._lock.release()

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

    def check_plan(self, cfg: FurnaceConfig, scenario: Scenario, budget: PlanBudget) -> None:
        """Raise ``twin.control.budget.PlanTooLarge`` (a ``ValueError``) if the run's first plan is estimated
        beyond ``budget``'s time or memory, so ``POST /api/runs`` answers 422 that says why."""
        from twin.control.reference import reference_trajectory
        from twin.control.replan import plan_estimate
        from twin.model.discrete import discrete_model

        model = discrete_model(cfg, self.radiation(cfg), None)  # same size and cost as the averaged one
        T0 = float(cfg.specimen.initial_temperature)
        ref = reference_trajectory(scenario.reference, T0)
        plan_estimate(model, cfg, ref, 0.0, t_stop=scenario.duration, budget=budget)

    def __call__(self, cfg: FurnaceConfig, scenario: Scenario, *, budget: PlanBudget) -> LoopLike:
        if self.processes:
            from backend.process_loop import ProcessLoop

            self.radiation(cfg, budget)  # the child loads it from the disk cache: make sure it is there
            return ProcessLoop(cfg, scenario, budget=budget,
                               niceness=MAX_SPEED_NICENESS if scenario.speed == "max" else 0)
        from twin.runs.loop import ClosedLoop

        # background=True: re-plans run in the loop's own thread, so a change never stalls the samples
        loop: LoopLike = ClosedLoop(cfg, scenario, radiation=self.radiation(cfg, budget), background=True,
                                    budget=budget)
        return loop
