"""The closed loop's plans and its live changes (``twin.runs.loop.ClosedLoop`` mixes in :class:`LiveChanges`).

A plan (:class:`_Plan`) is what depends on the model variant (fixed / averaged), the reference and the
calibrated parameters: the controller's model, the feedforward plan and the LQG gains for the rest of the
run (eqs. 18-29).  The loop makes its first plan when it is built; a live change
(:meth:`LiveChanges.set_reference`, :meth:`LiveChanges.set_oscillation`), a calibration that moved the
parameters, or a lamp group the fault detection found weak or failed asks for a new one from the current
estimate (:meth:`LiveChanges._request`, coalesced by :class:`twin.runs.replanning.Replanner`), and the
loop swaps it in at a sample boundary (:meth:`LiveChanges._install`), together with the reference and the
furnace's motion.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget
from twin.control.plan import plain_status
from twin.furnace.interface import Furnace
from twin.model.tables import Parameters
from twin.runs.fault_ride_through import faulty_model, reach_note
from twin.runs.record import RunRecord
from twin.runs.replanning import Replanner
from twin.scenario import OscillationSpec, Reference, Scenario, describe

log = logging.getLogger("twin.runs.loop")  # the loop's log, as before the split
Array = NDArray[np.float64]


@dataclass(frozen=True)
class _Plan:
    """What depends on the model variant (fixed / averaged) and the reference: immutable, shareable."""

    model: Any
    plan: Any
    gains: Any
    oscillation: OscillationSpec
    parameters: Parameters  # the calibrated deviations the controller's model was built with
    nominal: Any = None  # ``model`` without the lamp groups' faults (the fault detector's)
    note: str = ""  # what the groups left can hold, when the plan models a lamp group's lost power


class LiveChanges:
    """The closed loop's plans: the first, every re-plan a live change asks for, and swapping them in."""

    cfg: FurnaceConfig
    scenario: Scenario
    radiation: Any
    tables: Any  # twin.model.tables.ModelTables
    furnace: Furnace
    record: RunRecord
    controller: Any  # twin.control.lqg.Controller
    estimator: Any  # the primary estimator (twin.runs.estimators.RunEstimators.primary)
    estimators: Any  # twin.runs.estimators.RunEstimators
    detector: Any  # twin.estimation.fault_detection.FaultDetector
    j: int
    t_s: float
    n_steps: int
    _lock: threading.Lock
    _replanner: Replanner
    _events: list[str]
    _ctl: _Plan
    _oscillation: OscillationSpec
    _reference_spec: Reference
    _ref_fn: Callable[[Any], Any]
    _ref_samples: Any
    _T_range: tuple[float, float]
    _wanted_reference: tuple[Reference, Callable[[Any], Any]] | None
    _wanted_oscillation: OscillationSpec | None
    _lamp_gains: Any
    _lamps_change: str

    def _set_ref_fn(self, ref_fn: Callable[[Any], Any]) -> None:
        """Install T_ref(t) and its values at every sample time (one vectorised call, not one per step)."""
        self._ref_fn = ref_fn
        self._ref_samples = np.asarray(ref_fn(np.arange(self.n_steps + 1) * self.t_s), float)

    def _reachable_range(self) -> tuple[float, float]:
        """Fillet means the (nominal, fixed-specimen) model can hold: coldest surrounding .. full power."""
        from twin.control.reference import reachable_range
        from twin.model.discrete import discrete_model

        return reachable_range(discrete_model(self.cfg, self.radiation, None, tables=self.tables), self.cfg)

    def _make_reference(self, spec: Reference, T_initial: float, t_start: float) -> Callable[[Any], Any]:
        """T_ref(t) of run time; raises ValueError (ReferenceError) for unreachable temperatures."""
        from twin.control.reference import reference_trajectory

        return reference_trajectory(spec, T_initial, t_start=t_start, T_range=self._T_range)

    def _plan(
        self, spec: OscillationSpec, theta: Array, t0: float, ref_fn: Callable[[Any], Any], previous: Any,
        parameters: Parameters, budget: PlanBudget | None = None,
    ) -> _Plan:
        """Model (averaged over the motion, eq. 11, with the calibrated parameters), feedforward and gains
        for the rest of the run from t0 (eqs. 18-29)."""
        from twin.control.plan_model import plan_model
        from twin.control.replan import replan
        from twin.model.discrete import discrete_model

        nominal = discrete_model(self.cfg, self.radiation, spec if spec.enabled else None, tables=self.tables,
                                 parameters=parameters)
        gains_now = self._lamp_gains.copy()
        believed = faulty_model(nominal, gains_now)  # the groups as the fault detection believes them
        faulty = believed is not nominal
        model = plan_model(believed, self.cfg)  # with c_p(T) if [control] says so
        plan, gains = replan(model, self.cfg, theta, t0, ref_fn, previous, t_stop=self.scenario.duration,
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
        return _Plan(model, plan, gains, spec, parameters, nominal, note)

    # ------------------------------------------------------------------ live changes
    def set_reference(self, spec: Reference) -> Future[float]:
        """New reference from now on (times of a points reference count from now); re-plans.

        Raises ValueError, before anything changes, if the reference is unreachable.  Returns a future of
        the run time from which the reference (with its plan) is in force (:mod:`twin.runs.replanning`).
        """
        with self._lock:
            t_now = self.j * self.t_s
            T_now = float(self._ctl.model.c_m @ self.estimator.state.theta)
            ref_fn = self._make_reference(spec, T_now, t_start=t_now)
            self._wanted_reference = (spec, ref_fn)
            return self._request("reference", f"reference change requested at t = {t_now:.1f} s: {describe(spec)}")

    def set_oscillation(self, spec: OscillationSpec) -> Future[float]:
        """Switch the specimen motion; the motion, model, plan and gains switch together once re-planned.
        Returns a future of the run time from which it is in force."""
        with self._lock:
            t_now = self.j * self.t_s
            self._wanted_oscillation = spec
            return self._request("oscillation", f"oscillation {'on' if spec.enabled else 'off'} requested at "
                                                f"t = {t_now:.1f} s")

    def _request(self, kind: str, description: str) -> Future[float]:
        """Re-plan for the wanted reference and oscillation from the current estimate (coalesced)."""
        theta = self.estimator.state.theta.copy()
        t0 = self.j * self.t_s
        spec = self._wanted_oscillation or self._oscillation
        wanted_ref = self._wanted_reference
        ref_fn = wanted_ref[1] if wanted_ref is not None else self._ref_fn
        previous = self._ctl.plan
        parameters = self.estimator.parameters  # the controller's model follows the calibration
        self._events.append(description)

        def job(budget: PlanBudget) -> _Plan:
            return self._plan(spec, theta, t0, ref_fn, previous, parameters, budget=budget)

        def install(ctl: _Plan, kinds: list[str]) -> float:
            t = self.j * self.t_s  # the sample about to be computed is the first on the new plan
            if wanted_ref is not None and wanted_ref is self._wanted_reference:
                ref = wanted_ref[1]
                if t > t0 + 1e-9:
                    # planned from t0, in force from t (the furnace went on meanwhile): the new reference
                    # and its plan start at t, so a points reference's times count from the change in force
                    ref = self._make_reference(wanted_ref[0], float(np.asarray(ref(t0))), t_start=t)
                    ctl = dataclasses.replace(ctl, plan=ctl.plan.shifted(t - t0))
                self._reference_spec = wanted_ref[0]
                self._set_ref_fn(ref)
                self._wanted_reference = None
                self.record.note_change(t, "reference", wanted_ref[0].model_dump_json())  # the metric windows
            if spec is self._wanted_oscillation:
                self._wanted_oscillation = None
            if spec != self._oscillation:
                self._oscillation = spec
                self.furnace.set_oscillation(spec, t)
                self.record.note_change(t, "oscillation", spec.model_dump_json())
            ref_words = f" to {describe(self._reference_spec)}" if "reference" in kinds else ""
            how = f" ({describe(spec).removeprefix('on (')}" if spec.enabled else ""  # " (48 mm, 18 s)"
            said = {"reference": f"reference changed at t = {t:.1f} s{ref_words}",
                    "oscillation": f"oscillation {'on' if spec.enabled else 'off'} at t = {t:.1f} s{how}",
                    "calibration": f"calibration at t = {t:.1f} s",
                    "lamps": f"{self._lamps_change} from t = {t:.1f} s"}
            # a plan that models a lamp group's lost power: the integrator, which made up for it, starts at 0
            self._install(ctl, "; ".join(said.get(k, k) for k in kinds), fresh_integrator="lamps" in kinds)
            return t

        def fail(exc: BaseException, kinds: list[str]) -> None:  # back to what is in force
            self._wanted_reference, self._wanted_oscillation = None, None
            self._events.append(f"re-planning failed ({' and '.join(kinds)} not applied): {exc}")

        future = self._replanner.request(kind, job, install, fail)
        if future.done() and future.exception() is not None:  # inline (no background): raise as before
            raise future.exception()  # type: ignore[misc]
        return future

    def _install(self, ctl: _Plan, description: str, fresh_integrator: bool = False) -> None:
        """Swap in a new plan at a sample boundary; the integrator state carries over, unless the plan now
        models what the integrator was making up for (a lamp group's lost power): then it starts at 0."""
        motion_changed = ctl.oscillation != self._ctl.oscillation
        self._ctl = ctl
        self.controller = self.controller.with_plan(ctl.plan, ctl.gains, ctl.model)
        if fresh_integrator:
            from twin.control.lqg import IntegratorState

            self.controller.state = IntegratorState()
        if motion_changed:  # the averaged estimators switch to the new period average with the controller
            self.estimators.switch_motion(ctl.oscillation if ctl.oscillation.enabled else None)
            self.detector.set_model(ctl.nominal)
        self._events.append(f"re-planned ({description}): {plain_status(ctl.plan.status)}"
                            + (f"; {ctl.note}" if ctl.note else ""))
