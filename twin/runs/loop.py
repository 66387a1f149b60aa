"""The closed loop: plant -> three TCs -> EKF -> LQG + feedforward -> inputs -> plant.

This is the only module where the simulated furnace, its sensors, the estimator
and the controller meet (architecture.md).  Data flows one way; the plant's true
state never reaches the estimator or the controller: they see only the three TC
readings y_j and the inputs they applied themselves.

Per sample j (t_j = j t_s), following the paper's order (eqs. 13, 17, 25, 14):

1. the TCs read the plant at t_j (noise from the scenario's seed);
2. the EKF corrects its prior with y_j = (TC1, TC2, TC3)       (eq. 13);
3. the controller returns u_j = sat(u_ff_j + K_j e_j)          (eqs. 17, 25);
4. the plant integrates over [t_j, t_j + t_s] with u_j held    (zero-order hold);
5. the EKF predicts theta^-_{j+1} = F(theta_j, u_j)            (eq. 14).

Each call of :meth:`ClosedLoop.step` returns an immutable :class:`Snapshot` of
sample j.  Runs are deterministic for a seed.

Live changes (:meth:`ClosedLoop.set_reference`, :meth:`ClosedLoop.set_oscillation`)
take effect at the next sample: the reference (and the plant's motion) switch at
once, while the new feedforward, reference state, gains and model are re-planned
from the current estimate, in a background thread when ``background=True`` (the
backend) so the loop never stalls, and swapped in at the first sample after the
plan is ready.

Example
-------
>>> from twin.config import small_config
>>> from twin.scenario import Scenario
>>> loop = ClosedLoop(small_config(), Scenario(duration=1.0))  # doctest: +SKIP
>>> snaps = list(loop.run())                                    # doctest: +SKIP
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.runs.metrics import compute_metrics, fillet_mask, fillet_mean, sup_norm
from twin.scenario import OscillationSpec, Reference, Scenario

log = logging.getLogger(__name__)
Array = NDArray[np.float64]


@dataclass(frozen=True)
class Snapshot:
    """One sample of a run (all temperatures in K, powers as fractions of u_max)."""

    j: int
    t: float
    eta: float
    T_ref: float
    T_mean_hat: float
    field_hat: Array  # (N_y, N_x) estimate at the FD cell centres
    field_true: Array  # (N_y, N_x) plant state (only a simulation has it)
    tc: Array  # (4,) readings TC1..TC4
    tc_hat: Array  # (4,) estimate at xi_1..xi_4
    u: Array  # (6,) applied group powers
    u_ff: Array  # (6,) feedforward part
    inhomogeneity: float  # T_sup(t) of the estimate, K
    true_mean: float
    true_inhomogeneity: float
    events: tuple[str, ...] = ()


@dataclass(frozen=True)
class _Plan:
    """What depends on the model variant (fixed / averaged) and the reference: immutable, shareable."""

    model: Any
    plan: Any
    gains: Any


@dataclass
class _Pending:
    future: Future[_Plan]
    description: str


@dataclass
class _Series:
    t: list[float] = field(default_factory=list)
    eta: list[float] = field(default_factory=list)
    T_ref: list[float] = field(default_factory=list)
    T_mean_hat: list[float] = field(default_factory=list)
    tc: list[Array] = field(default_factory=list)
    tc_hat: list[Array] = field(default_factory=list)
    u: list[Array] = field(default_factory=list)
    u_ff: list[Array] = field(default_factory=list)
    field_hat: list[Array] = field(default_factory=list)
    field_true: list[Array] = field(default_factory=list)


def oscillation_of(spec: OscillationSpec, t0: float = 0.0) -> Callable[[float], float]:
    """eta(t) = A sin(2 pi (t - t0) / Pi) for an enabled spec, else eta = 0 (paper section 5.2)."""
    if not spec.enabled or spec.amplitude == 0.0:
        return lambda t: 0.0
    a, w = spec.amplitude, 2.0 * math.pi / spec.period
    return lambda t: a * math.sin(w * (t - t0))


class ClosedLoop:
    """Plant + TCs + EKF + feedforward/LQG for one scenario.

    Parameters
    ----------
    cfg : the furnace.
    scenario : the run (reference, duration, oscillation, TC4, mismatch, noise, seed).
    radiation : a shared :class:`twin.radiation.RadiationModel` (loaded from the cache if None).
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
        background: bool = False,
        plan_cache: dict[Any, _Plan] | None = None,
    ) -> None:
        from twin.control.lqg import Controller
        from twin.estimation.ekf import Estimator
        from twin.furnace.simulated.plant import Plant
        from twin.furnace.simulated.thermocouples import Thermocouples
        from twin.radiation import radiation_model

        self.cfg = cfg
        self.scenario = scenario
        self.t_s = cfg.sampling.t_s
        self.n_steps = int(round(scenario.duration / self.t_s))
        self.radiation: Any = radiation if radiation is not None else radiation_model(cfg)
        self._rng = np.random.default_rng(scenario.seed)
        self._lock = threading.Lock()
        self._executor = ThreadPoolExecutor(max_workers=1) if background else None
        self._pending: _Pending | None = None
        self._events: list[str] = []

        # --- the simulated furnace and its sensors (the "truth") ---
        self.plant = Plant(cfg, self.radiation, scenario.mismatch)
        positions = cfg.tc_positions(scenario.tc4)
        self.tc_positions = np.asarray(positions)
        self.thermocouples = Thermocouples(cfg, positions)
        self._T = np.full(cfg.specimen.n_states, cfg.specimen.initial_temperature)
        self._oscillation = scenario.oscillation
        self._eta_of_t = oscillation_of(scenario.oscillation)

        # --- the estimator and controller see only TC readings and their own inputs ---
        self.j = 0
        y0 = self._read_tcs(0.0)
        theta0 = np.full(self._fe_nodes(), float(np.mean(y0[:3])))
        self._reference_spec: Reference = scenario.reference
        self._T_range = self._reachable_range()
        self._set_ref_fn(self._make_reference(scenario.reference, float(np.mean(y0[:3])), t_start=0.0))
        key = (scenario.oscillation.model_dump_json(), repr(scenario.reference), theta0.tobytes())
        if plan_cache is not None and key in plan_cache:
            self._ctl = plan_cache[key]
        else:
            self._ctl = self._plan(scenario.oscillation, theta0, 0.0, self._ref_fn, previous=None)
            if plan_cache is not None:
                plan_cache[key] = self._ctl
        self.controller = Controller(self._ctl.model, self._ctl.plan, self._ctl.gains, cfg)
        self.estimator = Estimator(self._ctl.model, cfg, theta0)
        self._y_next = y0

        # --- output grid: FD cell centres ---
        s = cfg.specimen
        self.x = (np.arange(s.nx) + 0.5) * s.length / s.nx
        self.y = (np.arange(s.ny) + 0.5) * s.width / s.ny
        # the fillet's cells in the flat field
        self._fillet_idx = np.flatnonzero(fillet_mask(self.x, self.y, s.length, s.width).ravel())
        self._phi_tc = self._ctl.model.fe.phi(self.tc_positions)
        self._series = _Series()
        #: wall time of estimator + controller per sample (ms), for the benchmark
        self.compute_ms: list[float] = []

    # ------------------------------------------------------------------ helpers
    def _fe_nodes(self) -> int:
        fe = self.cfg.fe
        return len(fe.x_nodes) * len(fe.y_nodes)

    def _read_tcs(self, t: float) -> Array:
        return self.thermocouples.read(self._T, self._rng, self.scenario.tc_noise)

    def _set_ref_fn(self, ref_fn: Callable[[Any], Any]) -> None:
        """Install T_ref(t) and its values at every sample time (one vectorised call, not one per step)."""
        self._ref_fn = ref_fn
        self._ref_samples = np.asarray(ref_fn(np.arange(self.n_steps + 1) * self.t_s), float)

    def _reachable_range(self) -> tuple[float, float]:
        """Fillet means the (nominal, fixed-specimen) model can hold: coldest surrounding .. full power."""
        from twin.control.reference import reachable_range
        from twin.model.discrete import discrete_model

        return reachable_range(discrete_model(self.cfg, self.radiation, None), self.cfg)

    def _make_reference(self, spec: Reference, T_initial: float, t_start: float) -> Callable[[Any], Any]:
        """T_ref(t) of run time; raises ValueError (ReferenceError) for unreachable temperatures."""
        from twin.control.reference import reference_trajectory

        return reference_trajectory(spec, T_initial, t_start=t_start, T_range=self._T_range)

    def _plan(
        self, spec: OscillationSpec, theta: Array, t0: float, ref_fn: Callable[[Any], Any], previous: Any
    ) -> _Plan:
        """Model, feedforward and gains for the rest of the run from t0 (eqs. 11, 18-29)."""
        from twin.control.replan import replan
        from twin.model.discrete import discrete_model

        model = discrete_model(self.cfg, self.radiation, spec if spec.enabled else None)
        plan, gains = replan(model, self.cfg, theta, t0, ref_fn, previous)
        log.info(
            "plan from t = %.1f s: status %s, %s iterations, %.2f s",
            t0, plan.status, plan.iterations, plan.solve_s,
        )
        return _Plan(model, plan, gains)

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
            self._eta_of_t = oscillation_of(spec, t0=t_now)
            self._start_replan(spec, f"oscillation {'on' if spec.enabled else 'off'} at t = {t_now:.1f} s")

    def _start_replan(self, spec: OscillationSpec, description: str) -> None:
        theta = self.estimator.state.theta.copy()
        t0 = self.j * self.t_s
        ref_fn, previous = self._ref_fn, self._ctl.plan
        self._events.append(description)
        if self._executor is None:
            self._install(self._plan(spec, theta, t0, ref_fn, previous), description)
        else:
            fut = self._executor.submit(self._plan, spec, theta, t0, ref_fn, previous)
            self._pending = _Pending(fut, description)

    def _install(self, ctl: _Plan, description: str) -> None:
        """Swap in a new plan at a sample boundary; the integrator state carries over."""
        self._ctl = ctl
        self.controller = self.controller.with_plan(ctl.plan, ctl.gains, ctl.model)
        self.estimator.set_model(ctl.model)
        self._events.append(f"re-planned ({description}): {ctl.plan.status}")

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
        """Advance one sample; return the snapshot of sample j (before the plant moves on)."""
        if self.done:
            raise StopIteration("run finished")
        with self._lock:
            self._poll_pending()
            j, t = self.j, self.j * self.t_s
            eta = float(self._eta_of_t(t))
            y = self._y_next  # TC1..TC4 at t_j
            c0 = time.perf_counter()
            state = self.estimator.update(y[:3])  # eq. 13 (faulty readings gated inside)
            theta = state.theta
            ctl = self._ctl
            u, u_ff, _du = self.controller.control_at(t, theta)  # eqs. 17, 25
            compute_s = time.perf_counter() - c0
            T_ref = float(self._ref_samples[j])

            field_hat = ctl.model.fe.field_on_cells(theta)  # the cells are self.x, self.y
            field_true = self._T.reshape(self.cfg.specimen.ny, self.cfg.specimen.nx).copy()
            sup = float(sup_norm(field_hat.ravel(), T_ref, self._fillet_idx))
            events, self._events = tuple(self._events), []
            snap = Snapshot(
                j=j, t=t, eta=eta, T_ref=T_ref, T_mean_hat=float(ctl.model.c_m @ theta),
                field_hat=field_hat, field_true=field_true, tc=y.copy(), tc_hat=self._phi_tc @ theta,
                u=np.asarray(u, float).copy(), u_ff=np.asarray(u_ff, float).copy(), inhomogeneity=sup,
                true_mean=float(fillet_mean(self._T, self._fillet_idx)),
                true_inhomogeneity=float(sup_norm(self._T, T_ref, self._fillet_idx)),
                events=events,
            )
            self._record(snap)

            # the furnace moves on with u held over [t_j, t_j + t_s]; the EKF predicts (eq. 14)
            self._T = self.plant.step(self._T, snap.u, t, self.t_s, self._eta_of_t)
            c0 = time.perf_counter()
            self.estimator.predict(snap.u)
            self.compute_ms.append(1000.0 * (compute_s + time.perf_counter() - c0))
            self.j += 1
            self._y_next = self._read_tcs(self.j * self.t_s)
            return snap

    def run(self) -> Iterator[Snapshot]:
        while not self.done:
            yield self.step()

    def close(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)

    # ------------------------------------------------------------------ results
    def _record(self, s: Snapshot) -> None:
        r = self._series
        r.t.append(s.t)
        r.eta.append(s.eta)
        r.T_ref.append(s.T_ref)
        r.T_mean_hat.append(s.T_mean_hat)
        r.tc.append(s.tc)
        r.tc_hat.append(s.tc_hat)
        r.u.append(s.u)
        r.u_ff.append(s.u_ff)
        r.field_hat.append(s.field_hat.astype(np.float32))
        r.field_true.append(s.field_true.astype(np.float32))

    @property
    def t_E(self) -> float:
        return float(self.scenario.reference.t_E)

    @property
    def setpoint(self) -> float:
        return float(self.scenario.reference.setpoint)

    def timeseries(self) -> dict[str, Any]:
        """Everything recorded so far, in the ``timeseries.npz`` layout of product.md."""
        with self._lock:
            r = self._series
            n = len(r.t)
            s = self.cfg.specimen
            shape_f = (0, s.ny, s.nx)
            return {
                "t": np.asarray(r.t, float),
                "eta": np.asarray(r.eta, float),
                "T_ref": np.asarray(r.T_ref, float),
                "T_mean_hat": np.asarray(r.T_mean_hat, float),
                "tc": np.asarray(r.tc, float).reshape(n, 4),
                "tc_hat": np.asarray(r.tc_hat, float).reshape(n, 4),
                "u": np.asarray(r.u, float).reshape(n, -1) if n else np.zeros((0, self.cfg.n_groups)),
                "u_ff": np.asarray(r.u_ff, float).reshape(n, -1) if n else np.zeros((0, self.cfg.n_groups)),
                "t_field": np.asarray(r.t, float),
                "field_hat": np.asarray(r.field_hat, np.float32) if n else np.zeros(shape_f, np.float32),
                "field_true": np.asarray(r.field_true, np.float32) if n else np.zeros(shape_f, np.float32),
                "x": self.x,
                "y": self.y,
                "tc_positions": self.tc_positions,
                "L_s": s.length,
                "W_s": s.width,
                "t_E": self.t_E,
                "setpoint": self.setpoint,
                "group_names": np.asarray([g.name for g in self.cfg.lamps.groups]),
                "scenario": self.scenario.to_json(),
            }

    def metrics(self) -> dict[str, float]:
        return compute_metrics(self.timeseries())


def save_timeseries(path: Any, ts: Mapping[str, Any], *, compress: bool = True) -> None:
    """Write a time series atomically (tmp file, fsync, rename): a reader or a crash never sees half a file.

    ``compress=False`` for frequent rewrites of a growing run (the backend's flush every 2 s).
    """
    import os
    from pathlib import Path

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp.npz")
    save = np.savez_compressed if compress else np.savez
    with open(tmp, "wb") as fh:
        save(fh, **{k: np.asarray(v) for k, v in ts.items()})  # type: ignore[arg-type]
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, p)
