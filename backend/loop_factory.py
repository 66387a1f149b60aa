"""The loop factory of the server: real ``twin.runs.loop.ClosedLoop`` runs sharing one radiation model."""

from __future__ import annotations

import logging
import threading
from typing import Any

from backend.run_worker import LoopLike
from twin.config import FurnaceConfig
from twin.scenario import Reference, Scenario

log = logging.getLogger(__name__)


class DefaultLoopFactory:
    """Builds ``twin.runs.loop.ClosedLoop`` runs sharing one radiation model (loaded once, lazily)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._radiation: dict[str, Any] = {}
        self._T_range: dict[str, tuple[float, float]] = {}

    def radiation(self, cfg: FurnaceConfig) -> Any:
        from twin.radiation import radiation_model  # type: ignore[attr-defined]  # lands with the radiation part

        key = cfg.digest()
        with self._lock:
            if key not in self._radiation:
                self._radiation[key] = radiation_model(cfg)
            return self._radiation[key]

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

    def __call__(self, cfg: FurnaceConfig, scenario: Scenario) -> LoopLike:
        from twin.runs.loop import ClosedLoop

        # background=True: re-plans run in the loop's own thread, so a change never stalls the samples
        loop: LoopLike = ClosedLoop(cfg, scenario, radiation=self.radiation(cfg), background=True)
        return loop
