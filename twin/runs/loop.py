"""The closed loop: furnace -> three TCs -> EKF -> LQG + feedforward -> group powers -> furnace.

This is the only module where a furnace (:class:`twin.furnace.interface.Furnace`: the
simulated one, or a real one) and the twin (estimator and controller) meet (architecture.md).
Data flows one way; the furnace's state never reaches the estimator or the controller: they
see only the TC readings and the inputs they applied themselves.  A simulated furnace's
true field is recorded beside the estimate for the metrics, nothing more.

Per sample j (t_j = j t_s), following the paper's order (eqs. 13, 17, 25, 14):

1. the furnace's TCs are read at t_j (value, timestamp, status per TC);
2. the EKF corrects its prior with the usable ones of y_j = (TC1, TC2, TC3)   (eq. 13);
3. the controller returns u_j = sat(u_ff_j + K_j e_j)                       (eqs. 17, 25);
4. the furnace holds u_j over [t_j, t_j + t_s] (zero-order hold);
5. the EKF predicts theta^-_{j+1} = F(theta_j, u_j)                         (eq. 14).

Each call of :meth:`ClosedLoop.step` returns an immutable :class:`Snapshot` of
sample j.  Runs are deterministic for a seed.

A real-time furnace (:attr:`twin.furnace.interface.Furnace.realtime`, one over OPC UA) paces the loop:
reading the TCs waits in the furnace's ``read`` for the sample (never on a server's event loop: the caller's thread
waits).  A sample whose readings did not all come in time (status "missing") is *late*: the EKF
updates with what came, or only predicts; late samples are counted (:attr:`ClosedLoop.late_samples`,
``Snapshot.late_samples``) and reported as events when a run of them starts and ends.  The first
``read(0.0)`` at construction gives the initial estimate; the first step reads t = 0 again, which
starts a real-time furnace's clock after the (seconds-long) first plan.

Live changes (:meth:`ClosedLoop.set_reference`, :meth:`ClosedLoop.set_oscillation`) are
re-planned (feedforward, reference state, gains, model) from the current estimate, in a
background thread when ``background=True`` (the backend) so the loop never stalls, and take
effect together -- reference, furnace motion and plan -- at the first sample after the plan is
ready (:mod:`twin.runs.replanning`: the latest change wins, a failed re-plan changes nothing).

The loop composes its collaborators: ``self.changes`` (:class:`twin.runs.live_changes.LiveChanges`: the plan
and the reference in force, the re-plans) and ``self.faults`` (:class:`twin.runs.fault_ride_through.FaultRideThrough`:
the detector's decisions, fault injection).  Each sees the loop through a small protocol
(:class:`twin.runs.live_changes.PlanHost`, a ``note`` callable); the loop's lock is taken around every call
that may install a plan.
Each returns a future of the run time of the first sample that uses the change (a points reference's
times count from there; a plan made for an earlier sample moves there with its reference).  Plans never reach
far beyond the run's end, and a :class:`twin.control.budget.PlanBudget` bounds and cancels them.

Example
-------
>>> from twin.config import small_config
>>> from twin.scenario import Scenario
>>> loop = ClosedLoop(small_config(), Scenario(duration=0.5, reference={"setpoint": 400.0, "t_E": 10.0}))
>>> snaps = list(loop.run())
>>> len(snaps), snaps[-1].t, loop.record.arrays()["T_mean_hat"].shape
(6, 0.5, (6,))
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future
from pathlib import Path
from typing import Any, cast

import numpy as np

from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget
from twin.control.position_feedforward import PositionFeedforward
from twin.estimation.consistency import cell_nees
from twin.estimation.uncertainty import FieldUncertainty
from twin.events import RunEvent
from twin.furnace.interface import FaultInjectable, Furnace, Readings, delivered
from twin.model.tables import Parameters
from twin.physics.fillet import Fillet
from twin.physics.grid import cell_centers
from twin.runs.estimators import RunEstimators
from twin.runs.fault_ride_through import FaultRideThrough
from twin.runs.guards import DivergenceGuard, EstimateDiverged
from twin.runs.live_changes import LiveChanges, Plan
from twin.runs.metrics import LAMPS_OFF_WINDOW_S
from twin.runs.outage import BlindWatch, blind_cause, run_ending
from twin.runs.record import RunHeader, RunRecord, Snapshot
from twin.runs.series_store import SeriesStore, append_series
from twin.scenario import FaultSpec, OscillationSpec, Reference, Scenario

__all__ = ["ClosedLoop", "Snapshot"]


class ClosedLoop:
    """A furnace + EKF + feedforward/LQG for one scenario.

    Parameters
    ----------
    cfg : the furnace's configuration (the twin's model is built from it).
    scenario : the run (reference, duration, oscillation, TC4, mismatch, noise, seed).
    radiation : the twin's :class:`twin.radiation.RadiationModel` (loaded from the cache if None).
    furnace : the furnace to run (default: the simulated furnace of the scenario, sharing ``radiation``).
    background : re-plan in a worker thread (backend) instead of inline (CLI, tests).
    plan_cache : shared between loops (the campaign): the initial plan of an identical start
        (same oscillation, reference and initial estimate) is solved once.
    budget : wall time, memory and cancellation of every plan of the run (:mod:`twin.control.budget`);
        the first plan uses it, each re-plan a child of it.  ``None``: no estimate, IPOPT's own limits.
    on_estimate : called at each sample with the estimates (primary, shadow or None) after the measurement
        update, before anything else uses them (the campaign reads them at its other TC4 places,
        :mod:`twin.experiments.campaign_places`); it must not change them.
    """

    def __init__(
        self,
        cfg: FurnaceConfig,
        scenario: Scenario,
        radiation: Any = None,
        *,
        furnace: Furnace | None = None,
        background: bool = False,
        plan_cache: dict[Any, Plan] | None = None,
        budget: PlanBudget | None = None,
        on_estimate: Callable[[np.ndarray, np.ndarray | None], None] | None = None,
    ) -> None:
        from twin.control.mpc import make_controller
        from twin.estimation.fault_detection import FaultDetector
        from twin.model.tables import model_tables
        from twin.radiation import radiation_model

        self.cfg = cfg
        self.scenario = scenario
        self.t_s = cfg.sampling.t_s
        self.n_steps = int(round(scenario.duration / self.t_s))
        self.radiation: Any = radiation if radiation is not None else radiation_model(cfg)
        if furnace is None:
            if scenario.plant.kind != "simulated":
                raise ValueError(f"a scenario with a {scenario.plant.kind} plant needs its furnace passed "
                                 "(twin.furnace.open_furnace)")
            from twin.furnace.simulated import SimulatedFurnace

            furnace = SimulatedFurnace.for_scenario(cfg, scenario, self.radiation)
        self.furnace: Furnace = furnace
        # asked once: isinstance against a runtime-checkable Protocol costs 0.1 ms, at every sample it was 1 % of one
        self._fault_account = isinstance(furnace, FaultInjectable)
        self.tables = model_tables(cfg, self.radiation)  # the twin's model terms at every position
        self._lock = threading.Lock()
        self._events: list[str] = []
        #: samples with a reading that did not come in time (a real-time furnace); ``_late_run`` the current run
        self.late_samples = 0
        self._late_run = 0

        # --- the estimator and controller see only TC readings and their own inputs ---
        self.j = 0
        y0 = furnace.read(0.0).for_estimator()
        T0 = float(np.nanmean(y0)) if np.isfinite(y0).any() else float(cfg.specimen.initial_temperature)
        theta0 = np.full(len(cfg.fe.x_nodes) * len(cfg.fe.y_nodes), T0)
        #: the plans, the reference in force and the live changes (the first plan is made here)
        self.changes = LiveChanges(self, cfg, scenario, self.radiation, self.tables, n_steps=self.n_steps,
                                   t_s=self.t_s, theta0=theta0, T0=T0, background=background, budget=budget,
                                   plan_cache=plan_cache)
        first = self.changes.current
        self.feedback = scenario.control.feedback or cfg.control.feedback
        self.controller = make_controller(self.feedback, first.model, first.plan, first.gains, cfg)
        #: the oscillating specimen's lamp powers follow its position (``[control] position_feedforward``)
        self.position_ff = self._position_feedforward(first.oscillation)
        self.estimators = RunEstimators(scenario.estimator, self.tables, scenario.oscillation, cfg, theta0)
        self.estimator = self.estimators.primary  # the one that feeds the controller
        self.detector = FaultDetector(cfg, first.nominal, n_parameters=self.estimator.k)
        #: what the loop does about the faults the detector finds
        self.faults = FaultRideThrough(furnace, self.detector, self.changes, self.note)
        self.faults.watch(0.0, self.changes.reference.t_end)

        # --- output grid: FD cell centres; the record of the run ---
        s = cfg.specimen
        self.x, self.y = cell_centers(cfg)
        self.fillet = Fillet.of(cfg)
        self.tc_positions = np.asarray(furnace.tc_positions, float)
        self._phi_tc = first.model.fe.phi(self.tc_positions)
        model_error = cfg.ekf.model_error  # the specimen's mode at the start (the estimator's reported P as well)
        self.uncertainty = FieldUncertainty(first.model.fe, 0.0 if model_error is None else
                                            model_error.for_mode(scenario.oscillation.enabled).representation_rms)
        self._has_truth = furnace.true_field() is not None
        # a simulated furnace left with every lamp off from the start: what no controller can undercut
        # (true_mean_lead_lamps_off_max, twin.runs.metrics)
        left_alone = getattr(furnace, "lamps_off_means", None)
        lamps_off = None if left_alone is None or not self._has_truth else np.asarray(left_alone(
            self.fillet.mean, min(int(round(LAMPS_OFF_WINDOW_S / self.t_s)), self.n_steps) + 1), float)
        header = RunHeader(
            x=self.x, y=self.y, tc_positions=self.tc_positions, L_s=s.length, W_s=s.width,
            t_E=float(scenario.reference.t_E), setpoint=float(scenario.reference.setpoint),
            group_names=tuple(g.name for g in cfg.lamps.groups), scenario=scenario.to_json(),
            true_mean_lamps_off=lamps_off,
        )
        # fields at every sample through the metrics' windows (up to 2 t_E), then one per second (memory)
        field_every, full_rate_until = max(1, round(1.0 / self.t_s)), 2.0 * float(scenario.reference.t_E)
        capacity = RunRecord.capacity_for(self.n_steps + 1, self.t_s, field_every, full_rate_until)
        self.record = RunRecord(header, has_truth=self._has_truth, field_every=field_every,
                                full_rate_until=full_rate_until, capacity=capacity)
        self._guard = DivergenceGuard.for_furnace(cfg, scenario.tc_noise)  # stops a diverging estimate
        self.blindness = BlindWatch(self.t_s)  # samples without a reading in the estimate: degraded, and why
        #: wall time of estimator + controller per sample (ms), for the benchmark
        self.compute_ms: list[float] = []
        self._series: SeriesStore | None = None  # the parts append_series writes
        self._on_estimate = on_estimate

    # ------------------------------------------------------------------ the loop
    @property
    def done(self) -> bool:
        return self.j > self.n_steps

    @property
    def paced_by_furnace(self) -> bool:
        """The furnace keeps real time: :meth:`step` waits for its samples (no speed applies)."""
        return bool(self.furnace.realtime)

    @property
    def degraded(self) -> bool:
        """No thermocouple reading has reached the estimate for a while (:mod:`twin.runs.outage`)."""
        return self.blindness.blind_since is not None

    def ending(self, end: str, error: str | None = None) -> tuple[str, str | None]:
        """``(status, status_reason)`` of this run ending as ``end`` (:func:`twin.runs.outage.run_ending`)."""
        return run_ending(end, error, self.blindness, max(self.j - 1, 0) * self.t_s)

    @property
    def replanning(self) -> bool:
        """A re-plan is being solved in the background (it is swapped in at the next sample when done)."""
        return self.changes.solving

    def step(self) -> Snapshot:
        """Advance one sample; return the snapshot of sample j (before the furnace moves on)."""
        if self.done:
            raise StopIteration("run finished")
        # a real-time furnace waits here for its sample: outside the lock, so readers are not held up
        readings = self.furnace.read(self.j * self.t_s)
        with self._lock:
            self.changes.poll()
            j, t = self.j, self.j * self.t_s
            self._note_lateness(readings, t)
            self._events.extend(self.furnace.drain_events())
            eta = self.furnace.motion(t).eta
            if self._fault_account:  # the furnace's own account of injected faults, for the record only
                self._events.extend(cast(FaultInjectable, self.furnace).take_fault_events())
            c0 = time.perf_counter()
            changes = self.changes
            self.faults.watch(t, changes.reference.t_end)
            y = self.detector.screen(t, readings.values, readings.status)  # TCs found faulty left out (NaN)
            theta_prior = self.estimator.state.theta.copy()
            holding = t >= changes.reference.t_end  # the reference holds still
            theta, shadow = self.estimators.update(y, learn=holding)  # eq. 13 (faulty readings gated inside)
            if self._on_estimate is not None:
                self._on_estimate(theta, shadow)
            info = self.estimator.last_info
            used = info is not None and bool(np.any(info.used))  # blind: no TC reading reached the estimate
            why = "" if used else blind_cause(readings.status, self.detector.excluded, info)
            self._events.extend(self.blindness.note(t, used, why))
            self.faults.on_detections(t, self.detector.update(t, theta_prior, self.estimator.last_info))
            due = None
            if not changes.busy and holding:
                T_ref_j = float(changes.ref_samples[j])
                settle = (float(changes.current.model.c_m @ theta) - T_ref_j) / T_ref_j
                due = self.estimators.calibration_due(t, changes.current.parameters, holding, settle)
            if due is not None:  # the controller's model follows the calibration (re-planned like a change)
                changes.request("calibration", due)
            ctl = changes.current
            u, u_ff, _du = self.controller.control_at(t, theta)  # eqs. 17, 25
            if self.position_ff is not None:  # the position's share of the heat input, fed forward
                u = self.position_ff.apply(theta, u, eta, self.estimator.parameters, changes.lamp_gains)
            compute_s = time.perf_counter() - c0
            T_ref = float(changes.ref_samples[j])

            field_hat = ctl.model.fe.field_on_cells(theta)  # the cells are self.x, self.y
            P = self.estimator.reported_P  # what the twin claims about its estimate (issue 25)
            field_sigma = self.uncertainty.field_sigma(P)
            truth = self.furnace.true_field()
            events, self._events = tuple(self._events), []
            snap = Snapshot(
                j=j, t=t, eta=eta, T_ref=T_ref, T_mean_hat=float(ctl.model.c_m @ theta),
                field_hat=field_hat, field_true=None if truth is None else truth.reshape(field_hat.shape),
                tc=np.where(readings.usable, readings.values, np.nan), tc_hat=self._phi_tc @ theta,
                u=np.asarray(u, float).copy(), u_ff=np.asarray(u_ff, float).copy(),
                inhomogeneity=float(self.fillet.sup(field_hat, T_ref)),
                true_mean=None if truth is None else float(self.fillet.mean(truth)),
                true_inhomogeneity=None if truth is None else float(self.fillet.sup(truth, T_ref)),
                events=events, tc_status=tuple(readings.status), late_samples=self.late_samples,
                blind_since=self.blindness.blind_since,
                field_sigma=field_sigma, sigma_mean=self.uncertainty.mean_sigma(P), nis=self.estimator.nis,
                nees=None if truth is None else float(cell_nees(field_hat, truth.reshape(field_hat.shape),
                                                                field_sigma, self.fillet.mask)),
                **self.estimators.outputs(shadow, self._phi_tc, ctl.model.fe),
            )
            problem = self._guard.check(snap, left_out=self.detector.excluded)
            if problem is not None:  # nothing of this sample reaches the furnace or the record
                self.furnace.apply(np.zeros_like(snap.u), t)
                raise EstimateDiverged(f"t = {t:.1f} s: {problem}; the lamps were switched off")
            self.record.append(snap)

            # the furnace holds u over [t_j, t_j + t_s]; the EKF predicts (eq. 14)
            self.furnace.apply(snap.u, t)
            c0 = time.perf_counter()
            # what the lamps are believed to deliver (a lamp group the fault detection found weak or failed; none
            # once a furnace out of reach has switched them off, as its watchdog does)
            self.estimators.predict(changes.lamp_gains * delivered(self.furnace, snap.u, t), eta)
            self.detector.predict(snap.u, theta, self.estimator.state.theta, self.estimator.parameter_jacobian)
            self.compute_ms.append(1000.0 * (compute_s + time.perf_counter() - c0))
            self.j += 1
            return snap

    def _position_feedforward(self, oscillation: OscillationSpec) -> PositionFeedforward | None:
        """The position's feedforward for a motion (None: switched off, or a fixed specimen)."""
        if not self.cfg.control.position_feedforward:
            return None
        return PositionFeedforward.of(self.tables, oscillation, self.cfg)

    def _note_lateness(self, readings: Readings, t: float) -> None:
        """Count a sample with missing readings; an event when a run of late samples starts and ends.  A sample
        with readings the link could not bring (``unlinked``) is neither late nor on time: a run of late samples
        that the link's loss interrupts ends when the readings are on time again."""
        missing = [f"TC{i + 1}" for i, st in enumerate(readings.status) if st == "missing"]
        if missing:
            self.late_samples += 1
            self._late_run += 1
            if self._late_run == 1:
                self._events.append(f"sample at t = {t:.1f} s late: no {', '.join(missing)} in time "
                                    "(the EKF predicts without them)")
        elif self._late_run and "unlinked" not in readings.status:
            self._events.append(f"samples on time again at t = {t:.1f} s after {self._late_run} late "
                                f"({self.late_samples} in this run)")
            self._late_run = 0

    def run(self) -> Iterator[Snapshot]:
        while not self.done:
            yield self.step()

    def close(self) -> None:
        self.changes.close()
        self.furnace.close()

    # ------------------------------------------------------------------ results
    def timeseries(self) -> dict[str, Any]:
        """Everything recorded so far, in the ``timeseries.npz`` layout of product.md (:mod:`twin.runs.record`)."""
        with self._lock:
            return self.record.arrays()

    def metrics(self) -> dict[str, Any]:
        return self.record.metrics()

    # ------------------------------------------------------------------ for the host (twin.runs.interface.Loop)
    def add_event(self, event: RunEvent) -> None:
        """An event of the host's (a change's outcome, the run's end) into the run record."""
        self.record.add_event(event)

    def append_series(self, folder: Path) -> None:
        """Append the samples since the last call to the series parts in ``folder`` (``twin.runs.series_store``)."""
        self._series = append_series(self._series, folder, self.record)

    def set_reference(self, spec: Reference) -> Future[float]:
        """New reference from now on (times of a points reference count from now); re-plans.

        Raises ValueError, before anything changes, if the reference is unreachable.  Returns a future of
        the run time from which the reference (with its plan) is in force (:mod:`twin.runs.replanning`).
        """
        with self._lock:
            return self.changes.set_reference(spec)

    def set_oscillation(self, spec: OscillationSpec) -> Future[float]:
        """Switch the specimen motion; the motion, model, plan and gains switch together once re-planned.
        Returns a future of the run time from which it is in force."""
        with self._lock:
            return self.changes.set_oscillation(spec)

    def set_faults(self, faults: Sequence[FaultSpec]) -> None:
        """Inject ``faults`` into the furnace from the next sample on (``at`` counts from then; empty clears).

        Raises ValueError for a furnace that faults cannot be injected into (a real one).
        """
        furnace = self.faults.injectable()
        with self._lock:
            furnace.set_faults(faults, self.j * self.t_s)

    def faults_in_force(self) -> list[FaultSpec]:
        """The faults injected into the furnace (``at`` in run time); none for a real furnace."""
        return self.faults.faults_in_force()

    # ------------------------------------------------------------------ for its collaborators (PlanHost, note)
    def sample_time(self) -> float:
        """Run time (s) of the sample about to be computed."""
        return self.j * self.t_s

    def estimate(self) -> tuple[np.ndarray, Parameters]:
        """The primary estimator's theta (a copy) and the parameters a re-plan takes (the learnt ones a plan may
        use, :meth:`twin.runs.estimators.RunEstimators.for_plan`)."""
        return self.estimator.state.theta.copy(), self.estimators.for_plan(self.changes.first_parameters)

    def note(self, text: str) -> None:
        """An event of the current sample (it goes out with the next snapshot)."""
        self._events.append(text)

    def in_force(self, t: float, kind: str, spec: Reference | OscillationSpec) -> None:
        """A new reference or oscillation in force from ``t``: the furnace moves so, the record's windows know."""
        if isinstance(spec, OscillationSpec):
            self.furnace.set_oscillation(spec, t)
        self.record.note_change(t, kind, spec.model_dump_json())

    def adopt(self, plan: Plan, *, motion_changed: bool, fresh_integrator: bool,
              carry_integrator: bool = False) -> None:
        """The controller on ``plan``; the integrator state carries over unless ``fresh_integrator`` (a plan that
        models what it was making up for: a lamp group's lost power) or ``carry_integrator`` (a plan of the same
        goal on a calibrated model: what the new feedforward carries comes off the integrator,
        :func:`twin.control.lqg.carried_integrator`); a new motion switches the averaged estimators and the
        detector to its period average with the controller."""
        old = self.controller
        self.controller = old.with_plan(plan.plan, plan.gains, plan.model)
        if fresh_integrator:
            from twin.control.lqg import IntegratorState

            self.controller.state = IntegratorState()
        elif carry_integrator:
            from twin.control.lqg import carried_integrator

            self.controller.state = carried_integrator(old.plan, old.gains, plan.plan, plan.gains, self.sample_time(),
                                                       self.estimator.state.theta, old.state)
        if motion_changed:
            self.estimators.switch_motion(plan.oscillation if plan.oscillation.enabled else None)
            self.position_ff = self._position_feedforward(plan.oscillation)
            self.detector.set_model(plan.nominal)
