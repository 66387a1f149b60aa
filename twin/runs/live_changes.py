"""The closed loop's plans and its live changes: :class:`LiveChanges`, a collaborator of ``twin.runs.loop.ClosedLoop``.

A plan (:class:`Plan`) is what depends on the model variant (fixed / averaged), the reference and the
calibrated parameters: the controller's model, the feedforward plan and the LQG gains for the rest of the
run (eqs. 18-29).  :class:`LiveChanges` makes the first plan when the loop is built; a live change
(:meth:`LiveChanges.set_reference`, :meth:`LiveChanges.set_oscillation`), a calibration that moved the
parameters, or a lamp group the fault detection found weak or failed (:meth:`LiveChanges.lamps_found`) asks for
a new one from the current estimate (:meth:`LiveChanges.request`, coalesced by
:class:`twin.runs.replanning.Replanner`), and it is swapped in at a sample boundary, together with the
reference and the furnace's motion.

What it asks of the loop it plans for is the :class:`PlanHost` protocol (the sample time, the estimate, an
event, a change in force, adopting a plan); it holds the plan in force, the reference in force and what the
lamp groups are believed to deliver.  The loop takes its lock around every call that may install a plan.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget
from twin.control.plan import plain_status
from twin.control.reference import ReferenceTrajectory
from twin.model.tables import Parameters
from twin.runs.fault_ride_through import faulty_model, reach_note
from twin.runs.replanning import Replanner
from twin.scenario import OscillationSpec, Reference, Scenario, describe

log = logging.getLogger("twin.runs.loop")  # the loop's log, as before the split
Array = NDArray[np.float64]


@dataclass(frozen=True)
class Plan:
    """What depends on the model variant (fixed / averaged) and the reference: immutable, shareable."""

    model: Any
    plan: Any
    gains: Any
    oscillation: OscillationSpec
    parameters: Parameters  # the calibrated deviations the controller's model was built with
    nominal: Any = None  # ``model`` without the lamp groups' faults (the fault detector's)
    note: str = ""  # what the groups left can hold, when the plan models a lamp group's lost power


class PlanHost(Protocol):
    """What :class:`LiveChanges` asks of the loop it plans for (``twin.runs.loop.ClosedLoop`` implements it)."""

    def sample_time(self) -> float:
        """Run time (s) of the sample about to be computed: the first a plan installed now is in force for."""
        ...

    def estimate(self) -> tuple[Array, Parameters]:
        """The primary estimator's state theta (a copy) and the parameters a re-plan takes: where it starts."""
        ...

    def note(self, text: str) -> None:
        """An event of the current sample."""
        ...

    def in_force(self, t: float, kind: str, spec: Reference | OscillationSpec) -> None:
        """A new reference or oscillation (``kind``) in force from run time ``t``."""
        ...

    def adopt(self, plan: Plan, *, motion_changed: bool, fresh_integrator: bool,
              carry_integrator: bool = False) -> None:
        """Run the controller (and, when the motion changed, the estimators and the detector) on ``plan``."""
        ...


class LiveChanges:
    """A run's plans: the first, every re-plan a live change asks for, and swapping them in (module docstring).

    Parameters
    ----------
    host : the loop (:class:`PlanHost`).
    cfg, scenario, radiation, tables : the loop's furnace, scenario and the twin's model terms.
    n_steps, t_s : the run's samples and sampling period.
    theta0 : the initial estimate the first plan starts from; ``T0`` its fillet mean's start of the reference.
    background, budget : re-plan in a worker thread; the plans' budget (:class:`twin.runs.replanning.Replanner`).
    plan_cache : shared between loops (the campaign): the first plan of an identical start is solved once.
    """

    def __init__(
        self, host: PlanHost, cfg: FurnaceConfig, scenario: Scenario, radiation: Any, tables: Any, *,
        n_steps: int, t_s: float, theta0: Array, T0: float, background: bool = False,
        budget: PlanBudget | None = None, plan_cache: dict[Any, Plan] | None = None,
    ) -> None:
        self._host = host
        self.cfg, self.radiation, self.tables = cfg, radiation, tables
        self.n_steps, self.t_s, self.duration = n_steps, t_s, scenario.duration
        self._replanner = Replanner(background, budget)
        self.oscillation: OscillationSpec = scenario.oscillation  #: the motion in force
        # a change waiting for its plan: (spec, T_ref(t)) and the oscillation, in force when it is installed
        self._wanted_reference: tuple[Reference, ReferenceTrajectory] | None = None
        self._wanted_oscillation: OscillationSpec | None = None
        #: believed fraction of each group's power (the fault detection's), and its latest decision in words
        self.lamp_gains = np.ones(cfg.n_groups)
        self._lamps_change = "lamp groups as the fault detection found them"
        self.reference_spec: Reference = scenario.reference  #: the reference in force, as asked
        self._T_range = self._reachable_range()
        self._set_reference(self._make_reference(scenario.reference, T0, t_start=0.0))
        key = (scenario.oscillation.model_dump_json(), repr(scenario.reference), theta0.tobytes(),
               scenario.control.model_dump_json())
        learnt = scenario.control.plan_parameters  # what earlier runs of this furnace learnt (calibration memory)
        first = Parameters() if learnt is None else Parameters(**learnt.model_dump())
        self.first_parameters = first  #: the first plan's parameters: what a re-plan keeps of what it does not learn
        if plan_cache is not None and key in plan_cache:
            self.current = plan_cache[key]
        else:
            self.current = self._plan(scenario.oscillation, theta0, 0.0, self.reference, None, first,
                                      budget=budget)
            if plan_cache is not None:
                plan_cache[key] = self.current

    # ------------------------------------------------------------------ the re-planning thread
    @property
    def solving(self) -> bool:
        """A re-plan is being solved in the background."""
        return self._replanner.solving

    @property
    def busy(self) -> bool:
        """A re-plan is asked for or being solved (a calibration waits for it)."""
        return self._replanner.busy

    def poll(self) -> None:
        """Install a re-plan that finished (the loop calls it at a sample boundary, under its lock)."""
        self._replanner.poll()

    def close(self) -> None:
        self._replanner.close()

    # ------------------------------------------------------------------ the reference and the plans
    def _set_reference(self, ref: ReferenceTrajectory) -> None:
        """Install T_ref(t) and its values at every sample time (one vectorised call, not one per step)."""
        self.reference = ref  #: T_ref(t) in force (run time)
        self.ref_samples = np.asarray(ref(np.arange(self.n_steps + 1) * self.t_s), float)

    def _reachable_range(self) -> tuple[float, float]:
        """Fillet means the (nominal, fixed-specimen) model can hold: coldest surrounding .. full power."""
        from twin.control.reference import reachable_range
        from twin.model.discrete import discrete_model

        return reachable_range(discrete_model(self.cfg, self.radiation, None, tables=self.tables), self.cfg)

    def _make_reference(self, spec: Reference, T_initial: float, t_start: float) -> ReferenceTrajectory:
        """T_ref(t) of run time; raises ValueError (ReferenceError) for unreachable temperatures."""
        from twin.control.reference import reference_trajectory

        return reference_trajectory(spec, T_initial, t_start=t_start, T_range=self._T_range)

    def _plan(
        self, spec: OscillationSpec, theta: Array, t0: float, ref_fn: Callable[[Any], Any], previous: Any,
        parameters: Parameters, budget: PlanBudget | None = None,
    ) -> Plan:
        """Model (averaged over the motion, eq. 11, with the calibrated parameters), feedforward and gains
        for the rest of the run from t0 (eqs. 18-29)."""
        from twin.control.plan_model import plan_model
        from twin.control.replan import replan
        from twin.model.discrete import discrete_model

        nominal = discrete_model(self.cfg, self.radiation, spec if spec.enabled else None, tables=self.tables,
                                 parameters=parameters)
        gains_now = self.lamp_gains.copy()
        believed = faulty_model(nominal, gains_now)  # the groups as the fault detection believes them
        faulty = believed is not nominal
        model = plan_model(believed, self.cfg)  # with c_p(T) if [control] says so
        plan, gains = replan(model, self.cfg, theta, t0, ref_fn, previous, t_stop=self.duration,
                             budget=budget, best_effort=faulty)
        log.info(
            "plan from t = %.1f s: status %s, %s iterations, %.2f s",
            t0, plan.status, plan.iterations, plan.solve_s,
        )
        note = ""
        if faulty:
            rest = np.append(np.arange(t0, self.n_steps * self.t_s, 1.0), self.n_steps * self.t_s)
            T_end = float(np.max(np.asarray(ref_fn(rest), float)))  # the hottest the rest of the run asks for
            note = reach_note(self.cfg, model, gains_now, T_end)
        return Plan(model, plan, gains, spec, parameters, nominal, note)

    # ------------------------------------------------------------------ live changes
    def set_reference(self, spec: Reference) -> Future[float]:
        """New reference from now on (times of a points reference count from now); re-plans.

        Raises ValueError, before anything changes, if the reference is unreachable.  Returns a future of
        the run time from which the reference (with its plan) is in force (:mod:`twin.runs.replanning`).
        """
        t_now = self._host.sample_time()
        theta, _ = self._host.estimate()
        T_now = float(self.current.model.c_m @ theta)
        ref_fn = self._make_reference(spec, T_now, t_start=t_now)
        self._wanted_reference = (spec, ref_fn)
        return self.request("reference", f"reference change requested at t = {t_now:.1f} s: {describe(spec)}")

    def set_oscillation(self, spec: OscillationSpec) -> Future[float]:
        """Switch the specimen motion; the motion, model, plan and gains switch together once re-planned.
        Returns a future of the run time from which it is in force."""
        t_now = self._host.sample_time()
        self._wanted_oscillation = spec
        return self.request("oscillation", f"oscillation {'on' if spec.enabled else 'off'} requested at "
                                           f"t = {t_now:.1f} s")

    def lamps_found(self, lamp_gains: Array, what: str, t: float) -> Future[float]:
        """The fault detection changed its belief of the lamp groups (``lamp_gains``, kept; ``what``: "T2h
        failed"): re-plan with it."""
        self.lamp_gains = lamp_gains
        self._lamps_change = f"lamp group {what}"
        return self.request("lamps", f"lamp group {what} at t = {t:.1f} s")

    def request(self, kind: str, description: str) -> Future[float]:
        """Re-plan for the wanted reference and oscillation from the current estimate (coalesced; a calibration's
        re-plan from the estimate moved to the reference's mean)."""
        theta, parameters = self._host.estimate()  # the controller's model follows the calibration
        t0 = self._host.sample_time()
        if kind == "calibration":
            # the same goal on a better model: planned from the held field's shape at the reference's mean, the
            # mean's error stays the feedback's (a plan from the estimate itself corrects it in its first seconds,
            # while the integrator still makes up for it: the lamps cut for 3 s, twin.control.lqg.carried_integrator)
            c_m = np.asarray(self.current.model.c_m, float)
            theta = theta - (float(c_m @ theta) - float(np.asarray(self.reference(t0)))) / float(c_m.sum())
        spec = self._wanted_oscillation or self.oscillation
        wanted_ref = self._wanted_reference
        ref_fn = wanted_ref[1] if wanted_ref is not None else self.reference
        previous = self.current.plan
        self._host.note(description)

        def job(budget: PlanBudget) -> Plan:
            return self._plan(spec, theta, t0, ref_fn, previous, parameters, budget=budget)

        def install(ctl: Plan, kinds: list[str]) -> float:
            t = self._host.sample_time()  # the sample about to be computed is the first on the new plan
            if wanted_ref is not None and wanted_ref is self._wanted_reference:
                ref = wanted_ref[1]
                if t > t0 + 1e-9:
                    # planned from t0, in force from t (the furnace went on meanwhile): the new reference
                    # and its plan start at t, so a points reference's times count from the change in force
                    ref = self._make_reference(wanted_ref[0], float(np.asarray(ref(t0))), t_start=t)
                    ctl = dataclasses.replace(ctl, plan=ctl.plan.shifted(t - t0))
                self.reference_spec = wanted_ref[0]
                self._set_reference(ref)
                self._wanted_reference = None
                self._host.in_force(t, "reference", wanted_ref[0])  # the metric windows
            if spec is self._wanted_oscillation:
                self._wanted_oscillation = None
            if spec != self.oscillation:
                self.oscillation = spec
                self._host.in_force(t, "oscillation", spec)
            ref_words = f" to {describe(self.reference_spec)}" if "reference" in kinds else ""
            how = f" ({describe(spec).removeprefix('on (')}" if spec.enabled else ""  # " (48 mm, 18 s)"
            said = {"reference": f"reference changed at t = {t:.1f} s{ref_words}",
                    "oscillation": f"oscillation {'on' if spec.enabled else 'off'} at t = {t:.1f} s{how}",
                    "calibration": f"calibration at t = {t:.1f} s",
                    "lamps": f"{self._lamps_change} from t = {t:.1f} s"}
            # a plan that models a lamp group's lost power: the integrator, which made up for it, starts at 0; a
            # calibration alone keeps the goal: the integrator takes what the new plan's input lacks at the switch
            self._install(ctl, "; ".join(said.get(k, k) for k in kinds), fresh_integrator="lamps" in kinds,
                          carry_integrator=set(kinds) == {"calibration"})
            return t

        def fail(exc: BaseException, kinds: list[str]) -> None:  # back to what is in force
            self._wanted_reference, self._wanted_oscillation = None, None
            self._host.note(f"re-planning failed ({' and '.join(kinds)} not applied): {exc}")

        future = self._replanner.request(kind, job, install, fail)
        if future.done() and future.exception() is not None:  # inline (no background): raise as before
            raise future.exception()  # type: ignore[misc]
        return future

    def _install(self, ctl: Plan, description: str, fresh_integrator: bool = False,
                 carry_integrator: bool = False) -> None:
        """Swap in a new plan at a sample boundary; the integrator state carries over, unless the plan now
        models what the integrator was making up for: a lamp group's lost power (it starts at 0), or the
        calibrated lamps (it takes what the new plan's input lacks at the switch: with the LQG no jump)."""
        motion_changed = ctl.oscillation != self.current.oscillation
        self.current = ctl
        self._host.adopt(ctl, motion_changed=motion_changed, fresh_integrator=fresh_integrator,
                         carry_integrator=carry_integrator)
        self._host.note(f"re-planned ({description}): {plain_status(ctl.plan.status)}"
                        + (f"; {ctl.note}" if ctl.note else ""))
