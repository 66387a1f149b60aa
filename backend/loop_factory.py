"""The loop factory of the server: real ``twin.runs.loop.ClosedLoop`` runs sharing one radiation model."""

from __future__ import annotations

import logging
import threading
from typing import Any

from backend.run_worker import LoopLike
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanCancelled
from twin.scenario import Reference, Scenario

log = logging.getLogger(__name__)


class DefaultLoopFactory:
    """Builds ``twin.runs.loop.ClosedLoop`` runs sharing one radiation model (loaded once, lazily)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._radiation: dict[str, Any] = {}
        self._T_range: dict[str, tuple[float, float]] = {}

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
                self._radiation[key] = radiation_model(cfg)
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
        from twin.runs.loop import ClosedLoop

        # background=True: re-plans run in the loop's own thread, so a change never stalls the samples
        loop: LoopLike = ClosedLoop(cfg, scenario, radiation=self.radiation(cfg, budget), background=True,
                                    budget=budget)
        return loop
