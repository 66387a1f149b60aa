"""The loop factory of the server: real ``twin.runs.loop.ClosedLoop`` runs sharing the radiation models (the
twin's and the simulated furnace's own, each loaded once per furnace), on the scenario's furnace (simulated,
or over OPC UA with the server's ``opcua`` settings)."""

from __future__ import annotations

import logging
import threading
from typing import Any

from backend.run_worker import LoopLike
from backend.settings import Settings
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanCancelled
from twin.scenario import OscillationSpec, Reference, Scenario

log = logging.getLogger(__name__)


class DefaultLoopFactory:
    """Builds ``twin.runs.loop.ClosedLoop`` runs sharing the radiation models (loaded once, lazily), on the
    scenario's furnace (:func:`twin.furnace.connect.open_furnace`; one over OPC UA with ``settings.opcua``)."""

    def __init__(self, settings: Settings | None = None) -> None:
        self.settings = settings or Settings()  # type: ignore[call-arg]  # defaults and environment
        self._lock = threading.Lock()
        self._radiation: dict[str, Any] = {}
        self._truth_radiation: dict[str, Any] = {}
        self._T_range: dict[str, tuple[float, float]] = {}
        self._models: dict[tuple[str, str], tuple[Any, tuple[float, float]]] = {}  # (model, hold range)

    def _shared(self, store: dict[str, Any], cfg: FurnaceConfig, load: Any, budget: PlanBudget | None) -> Any:
        """``store[cfg]``, loaded (or ray-traced) once by ``load(cfg)``; a run waiting for another caller's
        computation stops waiting when its ``budget`` is cancelled (Stop while starting)."""
        key = cfg.digest()
        while not self._lock.acquire(timeout=0.1):
            if budget is not None and budget.cancelled:
                raise PlanCancelled("stopped while the radiation model was being computed")
        try:
            if key not in store:
                store[key] = load(cfg)
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

        return self._shared(self._truth_radiation, cfg, truth_radiation, budget)

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

    def model(self, cfg: FurnaceConfig, oscillation: OscillationSpec | None) -> tuple[Any, tuple[float, float]]:
        """The twin's discrete model for ``oscillation`` (time-averaged if enabled, eq. 11) and its hold range
        (``twin.control.feasibility.hold_range``), cached per furnace and oscillation."""
        from twin.control.feasibility import hold_range
        from twin.model.discrete import discrete_model

        osc = oscillation if oscillation is not None and oscillation.enabled else None
        key = (cfg.digest(), "fixed" if osc is None else osc.model_dump_json())
        with self._lock:
            known = self._models.get(key)
        if known is None:
            model = discrete_model(cfg, self.radiation(cfg), osc)
            known = (model, hold_range(model, cfg))
            with self._lock:
                self._models[key] = known
                while len(self._models) > 16:
                    self._models.pop(next(iter(self._models)))
        return known

    def feasibility(self, cfg: FurnaceConfig, reference: Reference, duration: float,
                    oscillation: OscillationSpec | None = None, T_initial: float | None = None,
                    t_start: float = 0.0) -> Any:
        """Can the furnace follow ``reference`` (``twin.control.feasibility.check_transition``) over a run of
        ``duration`` s from ``t_start`` (a live change: from now at the current mean ``T_initial``)?
        ``None`` if the model cannot be built (the run's own build then reports the problem)."""
        from twin.control.feasibility import check_transition

        try:
            model, hold = self.model(cfg, oscillation)
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

    def __call__(self, cfg: FurnaceConfig, scenario: Scenario, *, budget: PlanBudget) -> LoopLike:
        from twin.furnace.connect import open_furnace
        from twin.runs.loop import ClosedLoop

        rad = self.radiation(cfg, budget)
        simulated_truth = scenario.plant.kind == "simulated" and scenario.truth == "independent"
        own = self.truth_radiation(cfg, budget) if simulated_truth else None  # a furnace over OPC UA has no truth
        furnace = open_furnace(cfg, scenario, rad, truth_radiation=own, opcua=self.settings.opcua,
                               data_dir=self.settings.data_dir)
        try:
            # background=True: re-plans run in the loop's own thread, so a change never stalls the samples
            loop: LoopLike = ClosedLoop(cfg, scenario, radiation=rad, furnace=furnace, background=True,
                                        budget=budget)
        except BaseException:
            furnace.close()
            raise
        return loop
