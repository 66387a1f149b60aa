"""The loop factory of the server: real ``twin.runs.loop.ClosedLoop`` runs sharing the radiation models (the
twin's and the simulated furnace's own, each loaded once per furnace), on the scenario's furnace (simulated,
or over OPC UA with the server's ``opcua`` settings).

The radiation models (exchange factors, ray-traced once per furnace and cached on disk) are loaded in a
background thread as soon as the server starts (:meth:`DefaultLoopFactory.start_warm_up`): the twin's, then
the simulated furnace's own (runs' default truth); until they are ready the server answers everything at
once, ``GET /api/health`` reports ``"radiation": "computing"`` with the progress, and new runs wait in the
status ``queued`` (backend.runs.manager).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, replace
from typing import Any, Literal

from backend.core.settings import Settings
from backend.runs.factory import LoopFactory
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanCancelled
from twin.runs.interface import Loop
from twin.scenario import OscillationSpec, PlanParameters, Reference, Scenario

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
    stage_started: float = 0.0  # time.monotonic() when the current stage (table) began

    @property
    def fraction(self) -> float:
        if self.state == "ready":
            return 1.0
        return self.done / self.total if self.total else 0.0

    @property
    def elapsed_s(self) -> float:
        return (self.finished if self.finished is not None else time.monotonic()) - self.started

    @property
    def remaining_s(self) -> float | None:
        """Seconds left in the current ray trace at the pace of its positions so far; ``None`` before the
        first position (or when not tracing)."""
        if self.state != "computing" or not self.done or not self.total or self.done >= self.total:
            return None
        pace = (time.monotonic() - self.stage_started) / self.done
        return pace * (self.total - self.done)


#: CPU priority of a run at speed max (os.nice): the server and the runs paced in real time come first
MAX_SPEED_NICENESS = 5


class DefaultLoopFactory(LoopFactory):
    """Builds the server's runs: a simulated furnace's ``twin.runs.loop.ClosedLoop`` in its own process
    (:class:`backend.runs.process_loop.ProcessLoop`, which reads the radiation models from the disk cache), or in
    the server's process with ``processes=False`` (sharing the radiation models loaded here); a run on a
    furnace over OPC UA (:func:`twin.furnace.connect.open_furnace`, ``settings.opcua``; real time, paced by
    the furnace) always in the server's process."""

    def __init__(self, settings: Settings | None = None, *, processes: bool = True) -> None:
        self.settings = settings or Settings()  # type: ignore[call-arg]  # defaults and environment
        self.processes = processes
        self._lock = threading.Lock()
        self._radiation: dict[str, Any] = {}
        self._truth_radiation: dict[str, Any] = {}
        self._T_range: dict[str, tuple[float, float]] = {}
        self._models: dict[tuple[str, str, str | None], tuple[Any, tuple[float, float]]] = {}  # (model, hold range)
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
            now = time.monotonic()
            self._status[key] = WarmUpStatus("computing", "waiting", started=now, stage_started=now)
        self._event(key).clear()  # a retry: wait again
        threading.Thread(target=self._warm_up, args=(cfg,), name="radiation-warm-up", daemon=True).start()

    def _warm_up(self, cfg: FurnaceConfig) -> None:
        key = cfg.digest()
        try:
            self.radiation(cfg)
            self._set(key, stage="building the model")
            self.reachable_range(cfg)
            self.truth_radiation(cfg)
            self._set(key, state="ready", stage="ready", finished=time.monotonic())
            log.info("radiation model ready (%.1f s)", self._status[key].elapsed_s)
        except Exception as exc:
            log.exception("loading the radiation model failed; runs will retry")
            from twin.radiation.workers import TraceFailed

            reason = str(exc) if isinstance(exc, TraceFailed) else f"{type(exc).__name__}: {exc}"
            self._set(key, state="failed", stage="failed", error=reason, finished=time.monotonic())
        finally:
            self._event(key).set()

    def retry_warm_up(self, cfg: FurnaceConfig) -> bool:
        """Start the warm-up of ``cfg`` again after it failed; False (nothing done) unless it failed."""
        key = cfg.digest()
        with self._status_lock:
            st = self._status.get(key)
            if st is None or st.state != "failed":
                return False
            del self._status[key]
        log.info("retrying the radiation model")
        self.start_warm_up(cfg)
        return True

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

    # ---- the models ----
    def _shared(self, store: dict[str, Any], cfg: FurnaceConfig, load: Any, budget: PlanBudget | None,
                what: str = "") -> Any:
        """``store[cfg]``, loaded (or ray-traced) once by ``load(cfg, on_position=...)``; a run waiting for
        another caller's computation stops waiting when its ``budget`` is cancelled (Stop while starting).
        During a warm-up the stages say ``what`` is loaded or traced, with the traced positions."""
        key = cfg.digest()
        while not self._lock.acquire(timeout=0.1):
            if budget is not None and budget.cancelled:
                raise PlanCancelled("stopped while the radiation model was being computed")
        try:
            if key not in store:
                if key in self._status:
                    self._set(key, stage=f"loading the cache{what}", done=0, total=0, stage_started=time.monotonic())

                def traced(done: int, total: int) -> None:
                    if key in self._status:
                        more = {"stage_started": time.monotonic()} if done == 0 else {}
                        self._set(key, stage=f"ray tracing{what}", done=done, total=total, **more)

                store[key] = load(cfg, on_position=traced)
            return store[key]
        finally:
            self._lock.release()

    def radiation(self, cfg: FurnaceConfig, budget: PlanBudget | None = None) -> Any:
        """The twin's radiation model of the furnace (see :meth:`_shared`)."""
        from twin.radiation import radiation_model  # type: ignore[attr-defined]  # lands with the radiation part

        return self._shared(self._radiation, cfg, radiation_model, budget)

    def truth_radiation(self, cfg: FurnaceConfig, budget: PlanBudget | None = None) -> Any:
        """The simulated furnace's own table (``[truth.radiation]``), for runs whose truth is independent."""
        from twin.furnace.simulated.truth import truth_radiation

        return self._shared(self._truth_radiation, cfg, truth_radiation, budget, " (the simulated furnace's own)")

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

    def model(self, cfg: FurnaceConfig, oscillation: OscillationSpec | None,
              parameters: PlanParameters | None = None) -> tuple[Any, tuple[float, float]]:
        """The model the twin plans with for ``oscillation`` (time-averaged if enabled, eq. 11; with the
        learnt ``parameters`` and c_p(T) if ``[control]`` says so) and its hold range
        (``twin.control.feasibility.hold_range``), cached per furnace, oscillation and parameters."""
        from twin.control.feasibility import hold_range
        from twin.control.plan_model import plan_model
        from twin.model.discrete import discrete_model
        from twin.model.tables import Parameters

        osc = oscillation if oscillation is not None and oscillation.enabled else None
        key = (cfg.digest(), "fixed" if osc is None else osc.model_dump_json(),
               None if parameters is None else parameters.model_dump_json())
        with self._lock:
            known = self._models.get(key)
        if known is None:
            learnt = None if parameters is None else Parameters(**parameters.model_dump())
            model = plan_model(discrete_model(cfg, self.radiation(cfg), osc, parameters=learnt), cfg)
            known = (model, hold_range(model, cfg))
            with self._lock:
                self._models[key] = known
                while len(self._models) > 16:
                    self._models.pop(next(iter(self._models)))
        return known

    def feasibility(self, cfg: FurnaceConfig, reference: Reference, duration: float,
                    oscillation: OscillationSpec | None = None, T_initial: float | None = None,
                    t_start: float = 0.0, parameters: PlanParameters | None = None) -> Any:
        """Can the furnace follow ``reference`` (``twin.control.feasibility.check_transition``) over a run of
        ``duration`` s from ``t_start`` (a live change: from now at the current mean ``T_initial``), on the
        model the run plans with (``parameters``: what earlier runs learnt) and within the plan's reserve?
        ``None`` if the model cannot be built (the run's own build then reports the problem)."""
        from twin.control.feasibility import check_transition

        try:
            model, hold = self.model(cfg, oscillation, parameters)
        except Exception:
            log.exception("cannot build the model for the feasibility check; the reference is not checked")
            return None
        return check_transition(model, cfg, reference, duration=duration, T_initial=T_initial, t_start=t_start,
                                hold=hold)

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

    def check_plant(self, cfg: FurnaceConfig, scenario: Scenario) -> None:
        """Raise (``ValueError`` / ``OSError`` with a message) if the scenario's furnace cannot be used; for a
        furnace over OPC UA this connects and finds its nodes, writing nothing (blocking: call it in a thread)."""
        from twin.furnace.connect import probe_furnace

        probe_furnace(cfg, scenario, opcua=self.settings.opcua, data_dir=self.settings.data_dir)

    def __call__(self, cfg: FurnaceConfig, scenario: Scenario, *, budget: PlanBudget) -> Loop:
        from twin.furnace.connect import open_furnace
        from twin.runs.loop import ClosedLoop

        rad = self.radiation(cfg, budget)
        simulated_truth = scenario.plant.kind == "simulated" and scenario.truth == "independent"
        own = self.truth_radiation(cfg, budget) if simulated_truth else None  # a furnace over OPC UA has no truth
        if self.processes and scenario.plant.kind == "simulated":
            # the child loads both tables from the disk cache, where they now are
            from backend.runs.process_loop import ProcessLoop

            return ProcessLoop(cfg, scenario, budget=budget,
                               niceness=MAX_SPEED_NICENESS if scenario.speed == "max" else 0)
        furnace = open_furnace(cfg, scenario, rad, truth_radiation=own, opcua=self.settings.opcua,
                               data_dir=self.settings.data_dir)
        try:
            # background=True: re-plans run in the loop's own thread, so a change never stalls the samples
            loop: Loop = ClosedLoop(cfg, scenario, radiation=rad, furnace=furnace, background=True,
                                        budget=budget)
        except BaseException:
            furnace.close()
            raise
        return loop
