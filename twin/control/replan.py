"""Re-planning during a run: new feedforward, reference state and gains from the estimate.

When the user changes the reference (setpoint, transition time, points) or the
oscillation (on/off, amplitude, period; a new time-averaged model, eq. 11), the rest
of the run gets a new plan: the OCP (20) from the current estimate theta_hat at the
current time, warm-started from the previous plan's v(t) and u_c (or inputs), and the
LQG gains (26), (29) along it.  The backend calls :func:`replan` in a worker thread
while the loop keeps running on the old plan; :meth:`twin.control.lqg.Controller.with_plan`
then swaps the plan in and keeps the integrator state e_I.

Example
-------
>>> from twin.config import small_config
>>> from twin.control.reference import reference_trajectory
>>> from twin.model.discrete import discrete_model
>>> from twin.radiation import radiation_model
>>> from twin.scenario import TransitionReference
>>> cfg = small_config()
>>> model = discrete_model(cfg, radiation_model(cfg))
>>> first = reference_trajectory(TransitionReference(setpoint=800.0, t_E=20.0), 300.0)
>>> plan, gains = replan(model, cfg, np.full(model.n, 300.0), 0.0, first)
>>> new_ref = reference_trajectory(TransitionReference(setpoint=700.0, t_E=10.0), 600.0, t_start=10.0)
>>> theta_hat = plan.theta_ref[plan.index_at(10.0)]
>>> plan2, gains2 = replan(model, cfg, theta_hat, 10.0, new_ref, plan)   # warm-started from the first plan
>>> plan2.t0, plan2.success, gains2.K.shape[1:]
(10.0, True, (6, 106))
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget, PlanEstimate
from twin.control.feedforward import solve_feedforward
from twin.control.lqg import Gains, lqg_gains
from twin.control.ocp_grid import RefFn, check_budget, plan_grid
from twin.control.plan import FeedforwardPlan

log = logging.getLogger(__name__)

#: Phi_j, Gamma_j of the LQG design are evaluated every this many samples and held
#: (1 s at t_s = 0.1 s).  Measured on the default furnace (1440-sample plan): the gains
#: differ from per-sample Jacobians by 0.14 % (max relative entry), and the design time
#: drops by the 1296 Jacobian evaluations it skips.
JACOBIAN_EVERY = 10


def replan(
    model: Any,
    cfg: FurnaceConfig,
    theta_hat: ArrayLike,
    t_now: float,
    reference_fn: RefFn,
    previous_plan: FeedforwardPlan | None = None,
    *,
    parametrized: bool = True,
    best_effort: bool = False,
    jacobian_every: int = JACOBIAN_EVERY,
    horizon: float | None = None,
    t_stop: float | None = None,
    budget: PlanBudget | None = None,
) -> tuple[FeedforwardPlan, Gains]:
    """Feedforward plan and LQG gains for the rest of a run (sections 4.1-4.2).

    Parameters
    ----------
    model : DiscreteModel
        The (possibly newly averaged) discrete model (12a) the plan is made for.
    cfg : FurnaceConfig
        Weights (``cfg.feedforward``, ``cfg.lqg``), t_s.
    theta_hat : array (n,)
        Current estimate (K): the initial state (20c) of the new plan.
    t_now : float
        Run time (s) at which the new plan starts (its sample 0).
    reference_fn : callable
        T_ref(t) (K) of run time (s); the horizon follows from its transition end.
    previous_plan : FeedforwardPlan, optional
        Warm start; None for the first plan of a run.
    parametrized, best_effort : bool
        As in :func:`twin.control.feedforward.solve_feedforward`.
    jacobian_every : int
        Hold of the LQG linearization (:data:`JACOBIAN_EVERY`).
    horizon : float, optional
        OCP horizon (s); default as in :func:`twin.control.feedforward.solve_feedforward`.
    t_stop : float, optional
        Run time (s) at which the run ends: nothing is planned much beyond it
        (:func:`twin.control.ocp_grid.plan_grid`).
    budget : PlanBudget, optional
        Wall time, memory and cancellation of this job (:mod:`twin.control.budget`).

    Returns
    -------
    (FeedforwardPlan, Gains)

    Raises
    ------
    twin.control.feedforward.FeedforwardError
        If IPOPT fails and ``best_effort`` is False (the loop then keeps the old plan).
    twin.control.budget.PlanTooLarge, twin.control.budget.PlanCancelled
        Beyond the budget, or cancelled (the loop keeps the old plan).
    """
    start = time.perf_counter()
    theta = np.asarray(theta_hat, float)
    plan = solve_feedforward(model, theta, t_now, reference_fn, cfg, warm_start=previous_plan,
                             parametrized=parametrized, best_effort=best_effort, horizon=horizon, t_stop=t_stop,
                             budget=budget)
    gains = lqg_gains(model, plan, cfg, jacobian_every=jacobian_every,
                      check=None if budget is None else (lambda: budget.check("the LQG design")))
    log.info(
        "re-plan at t = %.1f s (%s): %s, %d iterations, OCP %.2f s, gains %.2f s, total %.2f s",
        t_now, "warm" if previous_plan is not None else "cold", plan.status, plan.iterations,
        plan.solve_s, gains.design_s, time.perf_counter() - start,
    )
    return plan, gains


def plan_estimate(model: Any, cfg: FurnaceConfig, reference_fn: RefFn, t_now: float, *,
                  t_stop: float | None = None, budget: PlanBudget | None = None) -> PlanEstimate:
    """Size and typical cost of the plan :func:`replan` would make from ``t_now``: with a ``budget``, raises
    :class:`twin.control.budget.PlanTooLarge` beyond it (its memory is checked before one sweep is timed)."""
    grid = plan_grid(model, reference_fn, t_now, cfg, t_stop=t_stop)
    if budget is None:
        return grid.estimate(model, cfg, timed=True)
    return check_budget(grid, model, cfg, budget)


def replan_seconds(cfg: FurnaceConfig, radiation: Any) -> float:
    """Benchmark ``replan_s``: wall time (s) of a warm-started re-plan after a reference change.

    A default run (fixed specimen, 300 K -> setpoint in t_E) is planned first; at
    t = t_E / 2 the user lowers the setpoint by 100 K with a new transition of t_E / 2
    from the current mean.  The estimate is taken as the nominal state of the first
    plan at that time.  The figure is the time of :func:`replan` (OCP + gains).
    """
    from twin.control.reference import reference_trajectory
    from twin.model.discrete import discrete_model
    from twin.scenario import TransitionReference

    model = discrete_model(cfg, radiation, None)
    first = TransitionReference.model_validate({})
    T0 = cfg.specimen.initial_temperature
    theta0 = np.full(model.n, T0)
    plan0 = solve_feedforward(model, theta0, 0.0, reference_trajectory(first, T0), cfg, best_effort=True)
    t_now = 0.5 * first.t_E
    theta = plan0.theta_ref[plan0.index_at(t_now)]
    new = TransitionReference(setpoint=first.setpoint - 100.0, t_E=0.5 * first.t_E)
    ref = reference_trajectory(new, float(model.c_m @ theta), t_start=t_now)
    t = time.perf_counter()
    plan, _ = replan(model, cfg, theta, t_now, ref, plan0, best_effort=True)
    elapsed = time.perf_counter() - t
    log.info("replan_s = %.2f s (status %s, %d iterations)", elapsed, plan.status, plan.iterations)
    return elapsed
