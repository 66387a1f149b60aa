"""What a scenario or a live change must pass before it reaches a run: the furnace's and this server's
limits (``twin.limits``), the reachable range, the reference's feasibility on the model
(``twin.control.feasibility``, through the loop factory), and for a furnace over OPC UA this server's
allow-list and a probe of the furnace (:meth:`RunChecks.plant`).  Refusals are plain sentences that name the
field or the time; feasibility warnings go back to the caller and into the run's events."""

from __future__ import annotations

import asyncio
import functools
from typing import Any

from pydantic import ValidationError

from backend.core.messages import field_path, plain_message
from backend.core.settings import Settings
from backend.runs.factory import LoopFactory
from backend.runs.types import LimitExceeded
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget
from twin.limits import ScenarioLimits
from twin.runs.changes import ChangeRejected
from twin.scenario import FaultSpec, OscillationSpec, PlanParameters, Reference, Scenario, check, parse_faults


def refusal(notes: tuple[str, ...]) -> str:
    """The 422 message of a reference the furnace cannot follow by a wide margin."""
    return "reference: this furnace cannot follow it: " + "; ".join(notes)


def say(exc: ValidationError) -> str:
    """A pydantic error as one plain line that names each field."""
    return "; ".join(f"{field_path(e['loc'])}: {plain_message(e)}" for e in exc.errors())


class RunChecks:
    """The checks of one server (its furnace, limits, settings and loop factory)."""

    def __init__(self, cfg: FurnaceConfig, limits: ScenarioLimits, settings: Settings,
                 loop_factory: LoopFactory) -> None:
        self.cfg, self.limits, self.settings, self.loop_factory = cfg, limits, settings, loop_factory

    def limits_of(self, scenario: Scenario) -> None:
        """Raise :class:`LimitExceeded` if the scenario lies outside the furnace's or this server's limits."""
        try:
            check(scenario, self.limits)
        except ValidationError as exc:
            raise LimitExceeded(say(exc)) from None
        s = self.settings
        problems = []
        if scenario.duration > s.max_duration_s:
            problems.append(f"duration: {scenario.duration:g} s exceeds this server's limit of "
                            f"{s.max_duration_s:g} s")
        if scenario.speed != "max" and float(scenario.speed) > s.max_speed:
            problems.append(f"speed: {scenario.speed:g} exceeds this server's limit of {s.max_speed:g}")
        if problems:
            raise LimitExceeded("; ".join(problems))
        plant = scenario.plant
        if plant.kind == "opcua":
            from twin.furnace.connect import EndpointNotAllowed, check_endpoint

            try:
                check_endpoint(plant.endpoint, s.opcua)
            except EndpointNotAllowed as exc:
                raise LimitExceeded(f"plant.endpoint: {exc}") from None

    async def plant(self, scenario: Scenario) -> None:
        """A furnace over OPC UA reachable with every node the twin needs (the loop factory's ``check_plant``,
        off the event loop; it writes nothing); :class:`LimitExceeded` naming ``plant.endpoint`` if not."""
        if scenario.plant.kind == "simulated":
            return
        try:
            await asyncio.to_thread(self.loop_factory.check_plant, self.cfg, scenario)
        except (ValueError, OSError) as exc:
            raise LimitExceeded(f"plant.endpoint: {exc}") from None

    def change_limits(self, value: Reference | OscillationSpec | list[FaultSpec]) -> None:
        """Raise :class:`ChangeRejected` if a live change lies outside the furnace's limits (a fault list: its
        targets among this furnace's TCs and lamp groups, its sizes within range)."""
        try:
            if isinstance(value, list):
                parse_faults([f.model_dump(mode="json") for f in value], self.limits)
            else:
                check(value, self.limits)
        except ValidationError as exc:
            raise ChangeRejected(say(exc)) from None

    async def assess(self, reference: Reference, duration: float, oscillation: OscillationSpec, *,
                     T_initial: float | None = None, t_start: float = 0.0,
                     parameters: PlanParameters | None = None) -> Any:
        """The loop factory's feasibility verdict on a reference (``twin.control.feasibility.Feasibility``),
        off the event loop, on the model with what the twin has learnt (``parameters``); ``None`` if the
        factory has no such check."""
        learnt = {} if parameters is None else {"parameters": parameters}
        return await asyncio.to_thread(functools.partial(self.loop_factory.feasibility, self.cfg, reference, duration,
                                                         oscillation, T_initial, t_start, **learnt))

    async def _limits_and_range(self, scenario: Scenario) -> None:
        self.limits_of(scenario)
        try:  # off the event loop: the first call may load the radiation model
            await asyncio.to_thread(self.loop_factory.check_reference, self.cfg, scenario.reference)
        except ValueError as exc:
            raise LimitExceeded(f"reference: {exc}") from None
        # the first plan within this server's time and memory (twin.control.budget)
        budget = PlanBudget(self.settings.plan_max_s, self.settings.plan_max_mb)
        try:
            await asyncio.to_thread(self.loop_factory.check_plan, self.cfg, scenario, budget)
        except ValueError as exc:
            raise LimitExceeded(f"reference: {exc}") from None

    async def start(self, scenario: Scenario) -> tuple[str, ...]:
        """Everything a new run must pass; returns its feasibility warnings (:class:`LimitExceeded` if refused).
        All but :meth:`limits_of` need the radiation model (the run manager defers them during its warm-up)."""
        await self._limits_and_range(scenario)
        report = await self.assess(scenario.reference, scenario.duration, scenario.oscillation,
                                   parameters=scenario.control.plan_parameters)
        notes: tuple[str, ...] = () if report is None else tuple(report.messages)
        if report is not None and report.verdict == "refuse":
            raise LimitExceeded(refusal(notes))
        return notes

    async def preview(self, scenario: Scenario) -> dict[str, Any]:
        """What :meth:`start` would say, as JSON (``POST /api/feasibility``): ``verdict`` ok / warn / refuse,
        ``messages``, and the feasibility details (``best`` reachable mean, ``hold_range``).  While the radiation
        model warms up only the limits are checked: ``pending`` says so (the run would wait as ``queued``)."""
        if not self.loop_factory.ready(self.cfg):
            try:
                self.limits_of(scenario)
            except LimitExceeded as exc:
                refused = [str(exc)]
            else:
                refused = []
            return {"verdict": "refuse" if refused else "pending",
                    "messages": refused or ["the radiation model is still loading: the reference is checked when "
                                            "it is ready (a run started now waits as queued)"],
                    "worst": None, "first_t": None, "best": None, "hold_range": None}
        problem = None
        try:
            await self._limits_and_range(scenario)
        except LimitExceeded as exc:
            problem = str(exc)
        try:
            report = await self.assess(scenario.reference, scenario.duration, scenario.oscillation,
                                       parameters=scenario.control.plan_parameters)
        except ValueError:  # a reference the trajectory refuses: the limits said why
            report = None
        out: dict[str, Any] = {"verdict": "ok", "messages": [], "worst": None, "first_t": None, "best": None,
                               "hold_range": None}
        if report is not None:
            out.update(report.to_json())  # a refusal keeps its sentences as a list (the page lists them)
        if problem is not None:
            out.update(verdict="refuse", messages=[problem])
        return out

    async def reference_change(self, value: Reference, duration: float, oscillation: OscillationSpec,
                               T_now: float | None, t_next: float) -> tuple[str, ...]:
        """A new reference from the current mean ``T_now`` at the next sample ``t_next``: its warnings
        (:class:`ChangeRejected` if the furnace cannot follow it by a wide margin)."""
        report = await self.assess(value, duration, oscillation, T_initial=T_now, t_start=t_next)
        if report is None:
            return ()
        notes = tuple(report.messages)
        if report.verdict == "refuse":
            raise ChangeRejected("this furnace cannot follow the new reference: " + "; ".join(notes))
        return notes
