"""What the server asks of whatever builds its runs' loops: :class:`LoopFactory`.

The server builds a run's loop (``twin.runs.interface.Loop``) through a factory and asks it, before a run
starts, whether the furnace's model is ready and whether the scenario can be run.  Every question has an
answer here that accepts (a factory without a model to warm up is always ready, a factory without checks
refuses nothing); ``backend.runs.loop_factory.DefaultLoopFactory`` answers each with the furnace's model, the
tests' stand-in (``tests/backend/conftest.py::FakeFactory``) only what it needs.  The server calls these
methods and no others.
"""

from __future__ import annotations

import time
from typing import Any

from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget
from twin.runs.interface import Loop
from twin.scenario import OscillationSpec, PlanParameters, Reference, Scenario


class LoopFactory:
    """Builds a run's loop; its first plan keeps to ``budget`` and stops when the budget is cancelled."""

    def __call__(self, cfg: FurnaceConfig, scenario: Scenario, *, budget: PlanBudget) -> Loop:
        raise NotImplementedError(f"{type(self).__name__} builds no loops")

    # ---- the model's warm-up ----
    def ready(self, cfg: FurnaceConfig) -> bool:
        """A run can be built now without waiting for the furnace's model."""
        return True

    def wait_ready(self, cfg: FurnaceConfig, timeout: float) -> bool:
        """Block until the model is ready (or failed), at most ``timeout`` s; True if it is."""
        if self.ready(cfg):
            return True
        time.sleep(timeout)
        return self.ready(cfg)

    def warm_up_status(self, cfg: FurnaceConfig) -> Any:
        """Where the model's warm-up stands (``backend.runs.loop_factory.WarmUpStatus``); ``None``: no warm-up."""
        return None

    def start_warm_up(self, cfg: FurnaceConfig) -> None:
        """Begin loading the furnace's model in the background (the server answers meanwhile); none by default."""

    def retry_warm_up(self, cfg: FurnaceConfig) -> bool:
        """Start a failed warm-up again; False (nothing done) unless it failed: a factory without one never fails."""
        return False

    # ---- checks before a run (each raises ValueError with a message; OSError too for the furnace) ----
    def check_reference(self, cfg: FurnaceConfig, reference: Reference) -> None:
        """The reference lies within what the furnace can reach."""

    def check_plan(self, cfg: FurnaceConfig, scenario: Scenario, budget: PlanBudget) -> None:
        """The run's first plan fits ``budget``'s time and memory."""

    def check_plant(self, cfg: FurnaceConfig, scenario: Scenario) -> None:
        """The scenario's furnace can be used (a furnace over OPC UA: reachable, every node found)."""

    def feasibility(self, cfg: FurnaceConfig, reference: Reference, duration: float,
                    oscillation: OscillationSpec | None = None, T_initial: float | None = None,
                    t_start: float = 0.0, parameters: PlanParameters | None = None) -> Any:
        """The feasibility verdict on a reference (``twin.control.feasibility.Feasibility``) on the model with what
        the twin has learnt (``parameters``); ``None``: unchecked."""
        return None
