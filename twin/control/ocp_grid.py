"""The grid of the feedforward OCP (:mod:`twin.control.feedforward`): horizon, knots, Heun substeps.

Where and how finely a plan is made, before anything is solved: :func:`plan_grid` gives the
:class:`PlanGrid` of a plan from run time ``t0`` (horizon beta (transition end - t0), section 4.1, at least
:data:`SETTLE_TIME_CONSTANTS` fillet-mean time constants (:func:`mean_time_constant`), never far beyond
the run's end; knots every ``interval`` s, at most :data:`MAX_KNOTS`; Heun substeps that keep
h |lambda_max| <= :data:`HEUN_STEP_LIMIT`), :meth:`PlanGrid.estimate` its size and typical cost, and
:func:`check_budget` refuses a plan beyond a :class:`twin.control.budget.PlanBudget`.

Example
-------
>>> import numpy as np
>>> transition_end(lambda t: np.minimum(300.0 + 10.0 * np.asarray(t), 500.0), 0.0, 0.1)
20.0
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanEstimate
from twin.control.initial_guess import KnotGrid, knot_weights
from twin.control.shooting import CoarseShooting, ScaledDistribution
from twin.model.dynamics import DiscreteDynamics

Array = NDArray[np.float64]
RefFn = Callable[[Any], Any]

#: Width of the v-knot grid of the OCP (s).  A numerical choice, not a furnace parameter.
DEFAULT_INTERVAL_S = 1.0
#: Largest h |lambda_max| of the Heun substeps (stability limit of Heun on the real axis is 2).
HEUN_STEP_LIMIT = 1.0
#: Shortest OCP horizon in fillet-mean time constants (a re-plan at or after the end of a
#: transition still needs the settling; 2 tau = 86 % settled, a compromise with the re-plan time).
SETTLE_TIME_CONSTANTS = 2.0
#: Longest reference the horizon search looks at (s): scenario.MAX_DURATION_S.
MAX_REFERENCE_S = 3600.0
#: Most v-knots of one OCP.  The sweep's residual Jacobian and Hessian grow with K^2 (memory and
#: time); a longer horizon holds v over proportionally longer intervals (a multiple of t_s) instead.
#: 240 keeps the paper's run (beta t_E = 144 s) and transitions up to 200 s at the 1 s knots.
MAX_KNOTS = 240


def transition_end(ref: RefFn, t0: float, t_s: float) -> float:
    """Run time (s) from which T_ref is constant: ``ref.t_end`` if it has one, else found by scanning."""
    t_end = getattr(ref, "t_end", None)
    if t_end is not None:
        return float(t_end)
    t = t0 + np.arange(0.0, MAX_REFERENCE_S + t_s, t_s)
    T = np.asarray(ref(t), float)
    moving = np.nonzero(np.abs(T - T[-1]) > 1e-9 * max(1.0, abs(float(T[-1]))))[0]
    return float(t[moving[-1] + 1]) if moving.size else float(t0)


def mean_time_constant(model: DiscreteDynamics, theta: ArrayLike, u: ArrayLike) -> float:
    """tau (s) of the fillet mean: 1 / (-c_m^T J 1), J = (dF/dtheta - I) / t_s (eqs. 12a, 16, 19).

    -c_m^T J 1 is the rate (1/s) at which the fillet mean relaxes after a uniform
    temperature rise of the specimen, i.e. its net loss coefficient.
    """
    J = (np.asarray(model.jac_theta(np.asarray(theta, float), np.asarray(u, float)), float)
         - np.eye(model.n)) / model.t_s
    rate = -float(np.asarray(model.c_m, float) @ J @ np.ones(model.n))
    return 1.0 / max(rate, 1e-6)


def _fastest_rate(model: DiscreteDynamics, theta: Array, u: Array) -> float:
    J = (np.asarray(model.jac_theta(theta, u), float) - np.eye(model.n)) / model.t_s
    return float(np.max(np.abs(np.linalg.eigvals(J))))


@dataclass(frozen=True)
class PlanGrid:
    """Where and how finely a plan is made: horizon, knot interval and count, Heun substeps per knot."""

    t0: float
    horizon: float
    interval: float  # s, a multiple of t_s
    K: int
    n_heun: int
    t_end: float  # end of the reference's transition (s)
    T_final: float  # K
    T_hot: float  # hottest temperature planned for (K)

    def estimate(self, model: DiscreteDynamics, cfg: FurnaceConfig | None = None, *,
                 timed: bool = False, check: Callable[[], None] | None = None) -> PlanEstimate:
        """Size of the plan on this grid (:class:`twin.control.budget.PlanEstimate`); with ``timed=True``
        (needs ``cfg``) also its typical cost: one sweep of this OCP is run and timed (it allocates the
        arrays :attr:`PlanEstimate.memory_mb` counts: check that first), and a Jacobian pair and a Riccati step."""
        substeps = max(1, int(round(self.interval / model.t_s)))
        est = PlanEstimate(horizon_s=self.horizon, knots=self.K, substeps=self.K * self.n_heun,
                           samples=self.K * substeps, n=model.n, m=model.m)
        if not timed:
            return est
        assert cfg is not None
        th, u = np.full(model.n, self.T_final), np.full(model.m, 0.5)
        grid = KnotGrid(self.t0, model.t_s, substeps, self.K)
        inputs = ScaledDistribution(model.m, self.K, cfg.feedforward.smoothing)
        shooting = CoarseShooting(model, th, grid.dt, self.n_heun, np.full(self.K + 1, self.T_final),
                                  knot_weights(grid), cfg.feedforward.g0, cfg.feedforward.g1, inputs,
                                  check=check)
        p = np.concatenate([np.full(model.m, 1.0 / model.m), np.full(self.K, 0.5)])
        sweep_s = _seconds(lambda: shooting.sweep(p), repeat=1)
        jac_s = _seconds(lambda: (model.jac_theta(th, u), model.jac_u(th, u)))
        from twin.control.lqg import riccati_step

        n1 = model.n + 1
        P, Phi, Gam, Q = np.eye(n1), np.eye(n1), np.ones((n1, model.m)), np.eye(n1)
        riccati_s = _seconds(lambda: riccati_step(P, Phi, Gam, Q, 1.0))
        return dataclasses.replace(est, sweep_s=sweep_s, jacobian_s=jac_s, riccati_s=riccati_s)


def _seconds(f: Callable[[], Any], repeat: int = 5) -> float:
    """Median of ``repeat`` wall times of ``f()`` (s): the machine's speed now, load included."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def check_budget(grid: PlanGrid, model: DiscreteDynamics, cfg: FurnaceConfig, budget: PlanBudget) -> PlanEstimate:
    """Raise :class:`twin.control.budget.PlanTooLarge` if the plan on ``grid`` needs more memory than
    ``budget`` allows, or (then timed: one sweep) more time; returns the timed estimate."""
    budget.refuse_if_too_large(grid.estimate(model))
    est = grid.estimate(model, cfg, timed=True, check=budget.check_cancel)  # the estimate's time is not the plan's
    budget.refuse_if_too_large(est)
    return est


def plan_grid(model: DiscreteDynamics, T_ref_fn: RefFn, t0: float, cfg: FurnaceConfig, *,
              horizon: float | None = None, t_stop: float | None = None,
              interval: float = DEFAULT_INTERVAL_S, theta0: ArrayLike | None = None) -> PlanGrid:
    """The grid of the OCP from run time ``t0`` (no solving).

    Horizon: ``horizon`` if given, else beta (transition end - t0) (section 4.1), at least
    :data:`SETTLE_TIME_CONSTANTS` fillet-mean time constants at the final temperature; never beyond
    the run's end ``t_stop`` by more than one knot interval (the plan must cover the last sample; nothing
    after the run is worth computing).  Knots every ``interval`` s, or coarser so that there are at most
    :data:`MAX_KNOTS`.
    """
    t_s = model.t_s
    t_end = transition_end(T_ref_fn, t0, t_s)
    T_final = float(np.asarray(T_ref_fn(np.array([t_end])), float)[0])
    if horizon is None:
        theta_lin = np.full(model.n, T_final)
        horizon = max(cfg.feedforward.beta * (t_end - t0),
                      SETTLE_TIME_CONSTANTS * mean_time_constant(model, theta_lin, np.full(model.m, 0.5)))
    substeps = max(1, int(round(interval / t_s)))
    if t_stop is not None:
        horizon = min(horizon, max(t_stop - t0, 0.0) + substeps * t_s)
    substeps = max(substeps, int(math.ceil(horizon / (MAX_KNOTS * t_s) - 1e-9)))
    K = max(2, int(math.ceil(horizon / (substeps * t_s) - 1e-9)))
    t_knots = t0 + np.arange(K + 1) * substeps * t_s
    hot = [T_final, float(np.max(np.asarray(T_ref_fn(t_knots), float)))]
    if theta0 is not None:
        hot.append(float(np.max(np.asarray(theta0, float))))
    T_hot = max(hot)
    lam = _fastest_rate(model, np.full(model.n, T_hot), np.full(model.m, 0.5))
    n_heun = max(1, int(math.ceil(substeps * t_s * lam / HEUN_STEP_LIMIT)))
    return PlanGrid(float(t0), float(horizon), substeps * t_s, K, n_heun, t_end, T_final, T_hot)
