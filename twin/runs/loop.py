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

Live changes (:meth:`ClosedLoop.set_reference`, :meth:`ClosedLoop.set_oscillation`)
take effect at the next sample: the reference (and the furnace's motion) switch at
once, while the new feedforward, reference state, gains and model are re-planned
from the current estimate, in a background thread when ``background=True`` (the
backend) so the loop never stalls, and swapped in at the first sample after the
plan is ready.

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

import logging
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.furnace.interface import Furnace, Readings
from twin.model.tables import PARAMETERS, Parameters
from twin.physics.fillet import Fillet
from twin.physics.grid import cell_centers
from twin.runs.record import RunHeader, RunRecord, Snapshot
from twin.scenario import OscillationSpec, Reference, Scenario

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

__all__ = ["ClosedLoop", "Snapshot"]


@dataclass(frozen=True)
class _Plan:
    """What depends on the model variant (fixed / averaged) and the reference: immutable, shareable."""

    model: Any
    plan: Any
    gains: Any
    oscillation: OscillationSpec
    parameters: Parameters  # the calibrated deviations the controller's model was built with


@dataclass
class _Pending:
    future: Future[_Plan]
    description: str


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
    """

    def __init__(
        self,
        cfg: FurnaceConfig,
        scenario: Scenario,
        radiation: Any = None,
        *,
        furnace: Furnace | None = None,
        background: bool = False,
        plan_cache: dict[Any, _Plan] | None = None,
    ) -> None:
        from twin.control.lqg import Controller
        from twin.estimation.choice import build_estimator
        from twin.model.tables import model_tables
        from twin.radiation import radiation_model

        self.cfg = cfg
        self.scenario = scenario
        self.t_s = cfg.sampling.t_s
        self.n_steps = int(round(scenario.duration / self.t_s))
        self.radiation: Any = radiation if radiation is not None else radiation_model(cfg)
        if furnace is None:
            from twin.furnace.simulated import SimulatedFurnace

            furnace = SimulatedFurnace.for_scenario(cfg, scenario, self.radiation)
        self.furnace: Furnace = furnace
        self.tables = model_tables(cfg, self.radiation)  # the twin's model terms at every position
        self._lock = threading.Lock()
        self._executor = ThreadPoolExecutor(max_workers=1) if background else None
        self._pending: _Pending | None = None
        self._events: list[str] = []
        self._oscillation = scenario.oscillation

        # --- the estimator and controller see only TC readings and their own inputs ---
        self.j = 0
        self._readings: Readings | None = furnace.read(0.0)
        y0 = self._readings.for_estimator()
        T0 = float(np.nanmean(y0)) if np.isfinite(y0).any() else float(cfg.specimen.initial_temperature)
        theta0 = np.full(len(cfg.fe.x_nodes) * len(cfg.fe.y_nodes), T0)
        self._reference_spec: Reference = scenario.reference
        self._T_range = self._reachable_range()
        self._set_ref_fn(self._make_reference(scenario.reference, T0, t_start=0.0))
        key = (scenario.oscillation.model_dump_json(), repr(scenario.reference), theta0.tobytes())
        if plan_cache is not None and key in plan_cache:
            self._ctl = plan_cache[key]
        else:
            self._ctl = self._plan(scenario.oscillation, theta0, 0.0, self._ref_fn, None, Parameters())
            if plan_cache is not None:
                plan_cache[key] = self._ctl
        self.controller = Controller(self._ctl.model, self._ctl.plan, self._ctl.gains, cfg)
        spec = scenario.estimator
        self.estimator = build_estimator(spec, self.tables, scenario.oscillation, cfg, theta0)
        self.shadow = None if spec.shadow is None else build_estimator(
            spec.shadow, self.tables, scenario.oscillation, cfg, theta0)
        self._replan_threshold = cfg.calibration.replan_threshold
        self._replan_interval = cfg.calibration.replan_interval
        self._last_calibration_t = -np.inf

        # --- output grid: FD cell centres; the record of the run ---
        s = cfg.specimen
        self.x, self.y = cell_centers(cfg)
        self.fillet = Fillet.of(cfg)
        self.tc_positions = np.asarray(furnace.tc_positions, float)
        self._phi_tc = self._ctl.model.fe.phi(self.tc_positions)
        self._has_truth = furnace.true_field() is not None
        header = RunHeader(
            x=self.x, y=self.y, tc_positions=self.tc_positions, L_s=s.length, W_s=s.width,
            t_E=float(scenario.reference.t_E), setpoint=float(scenario.reference.setpoint),
            group_names=tuple(g.name for g in cfg.lamps.groups), scenario=scenario.to_json(),
        )
        self.record = RunRecord(header, has_truth=self._has_truth)
        #: wall time of estimator + controller per sample (ms), for the benchmark
        self.compute_ms: list[float] = []

    # ------------------------------------------------------------------ helpers
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

    def _plan(self, spec: OscillationSpec, theta: Array, t0: float, ref_fn: Callable[[Any], Any], previous: Any,
              parameters: Parameters) -> _Plan:
        """Model (averaged over the motion, eq. 11, with the calibrated parameters), feedforward and gains
        for the rest of the run from t0 (eqs. 18-29)."""
        from twin.control.replan import replan
        from twin.model.discrete import discrete_model

        model = discrete_model(self.cfg, self.radiation, spec if spec.enabled else None, tables=self.tables,
                               parameters=parameters)
        plan, gains = replan(model, self.cfg, theta, t0, ref_fn, previous)
        log.info(
            "plan from t = %.1f s: status %s, %s iterations, %.2f s",
            t0, plan.status, plan.iterations, plan.solve_s,
        )
        return _Plan(model, plan, gains, spec, parameters)

    # ------------------------------------------------------------------ live changes
    def set_reference(self, spec: Reference) -> None:
        """New reference from now on (times of a points reference count from now); re-plans.

        Raises ValueError, before anything changes, if the reference is unreachable.
        """
        with self._lock:
            t_now = self.j * self.t_s
            T_now = float(self._ctl.model.c_m @ self.estimator.state.theta)
            ref_fn = self._make_reference(spec, T_now, t_start=t_now)
            self._reference_spec = spec
            self._set_ref_fn(ref_fn)
            self._start_replan(self._oscillation, f"reference changed at t = {t_now:.1f} s")

    def set_oscillation(self, spec: OscillationSpec) -> None:
        """Switch the specimen motion now; model, plan and gains follow after re-planning."""
        with self._lock:
            t_now = self.j * self.t_s
            self._oscillation = spec
            self.furnace.set_oscillation(spec, t_now)
            self._start_replan(spec, f"oscillation {'on' if spec.enabled else 'off'} at t = {t_now:.1f} s")

    def _start_replan(self, spec: OscillationSpec, description: str) -> None:
        theta = self.estimator.state.theta.copy()
        t0 = self.j * self.t_s
        ref_fn, previous, params = self._ref_fn, self._ctl.plan, self.estimator.parameters
        self._events.append(description)
        if self._executor is None:
            self._install(self._plan(spec, theta, t0, ref_fn, previous, params), description)
        else:
            fut = self._executor.submit(self._plan, spec, theta, t0, ref_fn, previous, params)
            self._pending = _Pending(fut, description)

    def _install(self, ctl: _Plan, description: str) -> None:
        """Swap in a new plan at a sample boundary; the integrator state carries over."""
        motion_changed = ctl.oscillation != self._ctl.oscillation
        self._ctl = ctl
        self.controller = self.controller.with_plan(ctl.plan, ctl.gains, ctl.model)
        if motion_changed:  # the averaged estimators switch to the new period average with the controller
            for est in (self.estimator, self.shadow):
                if est is not None:
                    est.set_model(est.model.with_oscillation(ctl.oscillation if ctl.oscillation.enabled else None))
        self._events.append(f"re-planned ({description}): {ctl.plan.status}")

    def _follow_calibration(self, t: float) -> None:
        """Re-plan the controller when a calibrated parameter is known well (sigma below the threshold) and
        moved past the threshold since its plan, at most once per ``calibration.replan_interval``."""
        est = self.estimator
        if not est.k or self._pending is not None or t < self._last_calibration_t + self._replan_interval:
            return
        cal = est.calibration()
        planned = self._ctl.parameters
        if not any(v["sigma"] < self._replan_threshold
                   and abs(v["value"] - getattr(planned, name)) > self._replan_threshold for name, v in cal.items()):
            return
        self._last_calibration_t = t
        now = ", ".join(f"{k} {100 * v['value']:+.1f} % (+-{100 * v['sigma']:.1f})" for k, v in cal.items())
        self._start_replan(self._oscillation, f"calibration at t = {t:.1f} s: {now}")

    def _poll_pending(self) -> None:
        p = self._pending
        if p is None or not p.future.done():
            return
        self._pending = None
        try:
            self._install(p.future.result(), p.description)
        except Exception as exc:  # a failed re-plan keeps the old plan running
            log.exception("re-planning failed: %s", p.description)
            self._events.append(f"re-planning failed ({p.description}): {exc}")

    # ------------------------------------------------------------------ the loop
    @property
    def done(self) -> bool:
        return self.j > self.n_steps

    @property
    def replanning(self) -> bool:
        """A re-plan is being solved in the background (it is swapped in at the next sample when done)."""
        p = self._pending
        return p is not None and not p.future.done()

    def step(self) -> Snapshot:
        """Advance one sample; return the snapshot of sample j (before the furnace moves on)."""
        if self.done:
            raise StopIteration("run finished")
        with self._lock:
            self._poll_pending()
            j, t = self.j, self.j * self.t_s
            readings = self._readings if self._readings is not None else self.furnace.read(t)
            self._readings = None
            eta = self.furnace.motion(t).eta
            c0 = time.perf_counter()
            y = readings.for_estimator()
            state = self.estimator.update(y)  # eq. 13 (faulty readings gated inside)
            theta = state.theta
            self._follow_calibration(t)
            ctl = self._ctl
            u, u_ff, _du = self.controller.control_at(t, theta)  # eqs. 17, 25
            compute_s = time.perf_counter() - c0
            T_ref = float(self._ref_samples[j])

            field_hat = ctl.model.fe.field_on_cells(theta)  # the cells are self.x, self.y
            truth = self.furnace.true_field()
            shadow = None if self.shadow is None else self.shadow.update(y).theta
            events, self._events = tuple(self._events), []
            snap = Snapshot(
                j=j, t=t, eta=eta, T_ref=T_ref, T_mean_hat=float(ctl.model.c_m @ theta),
                field_hat=field_hat, field_true=None if truth is None else truth.reshape(field_hat.shape),
                tc=np.where(readings.usable, readings.values, np.nan), tc_hat=self._phi_tc @ theta,
                u=np.asarray(u, float).copy(), u_ff=np.asarray(u_ff, float).copy(),
                inhomogeneity=float(self.fillet.sup(field_hat, T_ref)),
                true_mean=None if truth is None else float(self.fillet.mean(truth)),
                true_inhomogeneity=None if truth is None else float(self.fillet.sup(truth, T_ref)),
                events=events, **self._estimator_outputs(shadow),
            )
            self.record.append(snap)

            # the furnace holds u over [t_j, t_j + t_s]; the EKF predicts (eq. 14)
            self.furnace.apply(snap.u, t)
            c0 = time.perf_counter()
            self.estimator.predict(snap.u, eta)
            self.compute_ms.append(1000.0 * (compute_s + time.perf_counter() - c0))
            if self.shadow is not None:
                self.shadow.predict(snap.u, eta)
            self.j += 1
            return snap

    def _estimator_outputs(self, shadow: Array | None) -> dict[str, Any]:
        """The snapshot fields of a calibrating estimator and of a shadow estimator (record.OPTIONAL_SERIES)."""
        out: dict[str, Any] = {}
        est = self.estimator
        if est.k:
            values, sigma = np.full(len(PARAMETERS), np.nan), np.full(len(PARAMETERS), np.nan)
            for i, (name, v) in enumerate(est.calibration().items()):
                values[PARAMETERS.index(name)], sigma[PARAMETERS.index(name)] = v["value"], v["sigma"]
                assert name == est.model.calibrated[i]
            out.update(parameters=values, parameter_sigma=sigma)
        if shadow is not None:
            fe = self._ctl.model.fe
            out.update(shadow_T_mean_hat=float(fe.c_m @ shadow), shadow_tc_hat=self._phi_tc @ shadow,
                       shadow_field_hat=fe.field_on_cells(shadow))
        return out

    def run(self) -> Iterator[Snapshot]:
        while not self.done:
            yield self.step()

    def close(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
        self.furnace.close()

    # ------------------------------------------------------------------ results
    def timeseries(self) -> dict[str, Any]:
        """Everything recorded so far, in the ``timeseries.npz`` layout of product.md (:mod:`twin.runs.record`)."""
        with self._lock:
            return self.record.arrays()

    def metrics(self) -> dict[str, Any]:
        return self.record.metrics()
