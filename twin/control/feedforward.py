"""Optimal feedforward control (paper section 4.1, eqs. 18-21): the plan u_ff, theta_ref.

The OCP (20) is posed for CasADi's ``nlpsol`` and solved by IPOPT:

    min  sum_j g0 e_j^2 + g1 kappa_j          e_j = c_m^T theta_j - T_ref,j  (19),
                                              kappa_j = theta_j^T W theta_j  (21)
    s.t. theta_j+1 = F(theta_j, sat(v_j u_c)),  theta_0 = theta0,
         max(u_c) = 1,  0 <= u_c <= 1                                         (20b-e)

over the horizon beta t_E.  Choices made to keep it small, smooth and fast:

* **Coarse grid, single shooting.**  N = beta t_E / t_s = 1440 samples of a 117-state
  model are too many for a multiple-shooting NLP within seconds.  v is held over
  intervals of ``interval`` s (default 1 s = 10 samples; held rather than linear, see
  :class:`twin.control.shooting.ScaledDistribution`), and the model's right-hand side
  f = (F(theta, u) - theta) / t_s of eq. (12a) is integrated over each interval with
  Heun's method (2nd order; substeps keep h |lambda_max| <= 1, inside its stability
  region).  Any explicit Runge-Kutta step has the same steady states as (12a).  The
  cost is the trapezoidal sum over the knots, per sample.  Only m + K parameters
  remain; :mod:`twin.control.shooting` returns the cost, its exact gradient (forward
  sensitivities, checked against an adjoint) and a Hessian: Gauss-Newton plus the
  exact curvature of the input map (saturation, product v d).  IPOPT gets them
  through CasADi callbacks (options ``grad_f``, ``hess_lag``).  Without the input
  curvature IPOPT needed hundreds of iterations; with it about 20-35.  The grid (horizon,
  knots, Heun substeps) comes from :mod:`twin.control.ocp_grid`.
* **Fine-grid plan.**  u_ff,j = sat(v_j u_c) with the exact sat of eq. (18) at every
  sample, theta_ref = the fine model (12a) driven by u_ff, T_mean = c_m^T theta_ref,
  and ``plan.max_mean_error`` = max_j |T_mean,j - T_ref,j| measures what the coarse
  OCP grid and the smoothing cost on the real discrete model.
* **Scale of u_c.**  The set {v u_c : v >= 0, max(u_c) = 1} equals {v d : v >= 0,
  d >= 0, eta^T d = 1} for any eta > 0: both are all non-negative directions.  IPOPT
  gets the linear (smooth) constraint eta^T d = 1 instead of the non-smooth max (20d),
  with eta_i the fillet-mean heating rate of group i (:func:`heating_efficiency`), so
  that v is nearly the mean heating power whatever the distribution (with 1^T d = 1
  the valley between d and v is curved and IPOPT crawls along it).  The solution is
  rescaled to u_c = d / max(d), v = v max(d): (20d) holds exactly, inputs unchanged.
* **Saturation.**  With v >= 0 and u_c >= 0 the lower bound of sat is never active;
  the upper one is replaced in the OCP by the smooth minimum
  ``(z + 1 - sqrt((z - 1)^2 + w^2)) / 2``, width w = ``cfg.feedforward.smoothing``
  (at most w/2 below min(z, 1)).
* **Reserve.**  With ``[control] feedforward_limit`` = s < 1 the OCP plans u' on the model
  F(theta, s u') (:class:`twin.control.plan_model.ScaledInputs`) and the plan is u_ff = s u':
  the feedforward never uses more than s u_max, the feedback keeps the rest.
* **Unparametrized OCP** (``parametrized=False``, Remark 4): free inputs held over the
  same intervals, 0 <= u <= 1; comparing the objectives shows what (18) trades away.

IPOPT's status and iteration count are reported in the plan; a failed solve raises
:class:`FeedforwardError` unless ``best_effort=True``.

Example
-------
>>> from twin.config import small_config
>>> from twin.control.reference import reference_trajectory
>>> from twin.model.discrete import discrete_model
>>> from twin.radiation import radiation_model
>>> from twin.scenario import TransitionReference
>>> cfg = small_config()
>>> model = discrete_model(cfg, radiation_model(cfg))
>>> ref = reference_trajectory(TransitionReference(setpoint=800.0, t_E=20.0), 300.0)
>>> plan = solve_feedforward(model, np.full(model.n, 300.0), 0.0, ref, cfg)
>>> plan.success, plan.u_ff.shape[1], bool(plan.max_mean_error < 5.0)   # K
(True, 6, True)
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget
from twin.control.initial_guess import V_MAX, KnotGrid, free_guess, heating_efficiency, knot_weights, parametrized_guess
from twin.control.ipopt_callbacks import casadi_objective, stop_when
from twin.control.ocp_grid import DEFAULT_INTERVAL_S, RefFn, check_budget, plan_grid
from twin.control.plan import FeedforwardError, FeedforwardPlan, saturation, simulate
from twin.control.plan_model import ScaledInputs
from twin.control.shooting import CoarseShooting, FreeInputs, ScaledDistribution
from twin.model.dynamics import DiscreteDynamics

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

#: rho of the Tikhonov term rho * mean_k(v_k^2) (K^2) added to (20a): far below one K^2 of
#: tracking error, it only removes the flat directions of v where every used group saturates
#: (there the cost does not depend on v and the Gauss-Newton Hessian is singular).
INPUT_REGULARIZATION = 1e-3


# --------------------------------------------------------------------------- helpers
def _ca() -> Any:
    import casadi

    return casadi


# --------------------------------------------------------------------------- the NLP
def _ipopt_options(max_iter: int, max_wall_s: float, extra: dict[str, Any] | None) -> dict[str, Any]:
    """IPOPT options (stack-notes.md).

    The adaptive barrier update suits the many bounds of (d, v).  Besides the strict
    stop (scaled KKT error < 1e-6, "Solve_Succeeded") IPOPT may stop early with
    "Solved_To_Acceptable_Level" once the objective changes by less than 2e-3
    (relative) in 3 consecutive iterations: the kinks of the (smoothed) saturation
    make IPOPT creep for tens of iterations over the last ~1 % of the objective
    (~0.4 K^2 per sample on the default run), which does not change the plan noticeably.
    """
    opts: dict[str, Any] = {
        "ipopt.print_level": 0,
        "print_time": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": max_iter,
        "ipopt.mu_strategy": "adaptive",
        "ipopt.tol": 1e-6,
        "ipopt.acceptable_tol": 1e6,  # the acceptable stop rests on the objective change (above)
        "ipopt.acceptable_obj_change_tol": 2e-3,
        "ipopt.acceptable_iter": 3,
        "ipopt.max_wall_time": max_wall_s,
        "error_on_fail": False,
        "show_eval_warnings": False,  # a cancelled budget raises in a callback: no page of CasADi's warning
    }
    opts.update(extra or {})
    return opts


def solve_feedforward(
    model: DiscreteDynamics,
    theta0: ArrayLike,
    t0: float,
    T_ref_fn: RefFn,
    cfg: FurnaceConfig,
    warm_start: FeedforwardPlan | None = None,
    parametrized: bool = True,
    *,
    horizon: float | None = None,
    interval: float = DEFAULT_INTERVAL_S,
    best_effort: bool = False,
    max_iter: int = 400,
    max_wall_s: float = 120.0,
    ipopt_options: dict[str, Any] | None = None,
    t_stop: float | None = None,
    budget: PlanBudget | None = None,
) -> FeedforwardPlan:
    """Solve the feedforward OCP (20) from theta0 at run time t0 and return the plan.

    Parameters
    ----------
    model : DiscreteModel
        Discrete model (12a) with ``casadi_step``, ``step``, ``jac_theta``, ``c_m``, ``W``.
    theta0 : array (n,)
        Initial state (K), eq. (20c): the estimate at t0.
    t0 : float
        Run time (s) of the first sample.
    T_ref_fn : callable
        T_ref(t) (K) of run time (s), e.g. :func:`twin.control.reference.reference_trajectory`.
    cfg : FurnaceConfig
        Weights g0, g1, beta and the smoothing width (``cfg.feedforward``), t_s.
    warm_start : FeedforwardPlan, optional
        A previous plan; its v(t) and u_c (or free inputs) start the iteration.
    parametrized : bool
        True: u_ff = sat(v_j u_c) (eq. 18); False: free inputs (Remark 4).
    horizon : float, optional
        OCP horizon (s); default beta * (transition end - t0) (section 4.1), at least
        2 time constants of the fillet mean at the final temperature
        (:func:`twin.control.ocp_grid.mean_time_constant`) so a late re-plan still covers the settling
        (:func:`twin.control.ocp_grid.plan_grid`).
    interval : float
        Knot spacing of v (s), a multiple of t_s; coarser when the horizon needs more than
        :data:`twin.control.ocp_grid.MAX_KNOTS` knots.
    best_effort : bool
        Return the last iterate (``success=False``) instead of raising when IPOPT fails.
    max_iter, max_wall_s : int, float
        IPOPT iteration and wall-time limits.
    ipopt_options : dict, optional
        Extra CasADi/IPOPT options (e.g. ``{"ipopt.print_level": 5}`` to debug).
    t_stop : float, optional
        Run time (s) at which the run ends: the horizon stops there (plus one knot interval).
    budget : PlanBudget, optional
        Time, memory and cancellation of this job (:mod:`twin.control.budget`); when given, its remaining wall
        time is IPOPT's limit instead of ``max_wall_s`` (a server's ``plan_max_s``, a campaign's
        :data:`twin.control.budget.BATCH_MAX_WALL_S`).

    Raises
    ------
    FeedforwardError
        When IPOPT does not report success and ``best_effort`` is False.
    PlanTooLarge
        (a ``ValueError``) before solving, when the plan is estimated beyond the budget; while solving,
        when the budget's wall time is spent.
    PlanCancelled
        When the budget's token is cancelled.
    """
    return _solve_feedforward(model, theta0, t0, T_ref_fn, cfg, warm_start, parametrized, horizon,
                              interval, best_effort, max_iter, max_wall_s, ipopt_options, t_stop, budget)


def _solve_feedforward(model: DiscreteDynamics, theta0: ArrayLike, t0: float, T_ref_fn: RefFn,
                       cfg: FurnaceConfig, warm_start: FeedforwardPlan | None, parametrized: bool,
                       horizon: float | None, interval: float, best_effort: bool, max_iter: int,
                       max_wall_s: float, ipopt_options: dict[str, Any] | None, t_stop: float | None,
                       budget: PlanBudget | None) -> FeedforwardPlan:
    ca = _ca()
    wall0 = time.perf_counter()
    fw = cfg.feedforward
    t_s = model.t_s
    th0 = np.asarray(theta0, float)
    if th0.shape != (model.n,) or not np.all(np.isfinite(th0)):
        raise ValueError(f"theta0 must be a finite vector of {model.n} temperatures")
    # the reserve: the OCP plans u' in [0, 1] on F(theta, limit u'); the plan applies limit u' (plan_model.py)
    limit = float(cfg.control.feedforward_limit)
    real_model, model = model, (model if limit >= 1.0 else ScaledInputs(model, limit))
    pg = plan_grid(model, T_ref_fn, t0, cfg, horizon=horizon, t_stop=t_stop, interval=interval, theta0=th0)
    if budget is not None:
        budget.check("the feedforward plan")
        check_budget(pg, model, cfg, budget)
        max_wall_s = max(budget.remaining_s, 1e-3)  # the job's own limit, not the interactive default
    horizon, substeps = pg.horizon, int(round(pg.interval / t_s))
    grid = KnotGrid(float(t0), t_s, substeps, pg.K)
    theta_lin, n_heun = np.full(model.n, pg.T_final), pg.n_heun

    T_knots = np.asarray(T_ref_fn(grid.t_knots), float)
    m = model.m
    inputs: ScaledDistribution | FreeInputs
    if parametrized:
        inputs = ScaledDistribution(m, grid.K, fw.smoothing)
        lbx = np.zeros(inputs.n_params)
        eta = heating_efficiency(model, theta_lin)
        with np.errstate(divide="ignore"):  # d_i <= 1 / eta_i from eta^T d = 1; a failed group's d_i = 0
            d_max = np.where(eta > 0, 1.0 / eta, 0.0)
        ubx = np.concatenate([d_max, np.full(grid.K, V_MAX)])
        x_init = parametrized_guess(model, grid, n_heun, T_knots, th0, warm_start, eta, fw.smoothing)
    else:
        inputs = FreeInputs(m, grid.K)
        lbx = np.zeros(inputs.n_params)
        ubx = np.ones(inputs.n_params)
        x_init = free_guess(model, grid, n_heun, T_knots, th0, warm_start, fw.smoothing)
    reg = np.full(inputs.n_params, INPUT_REGULARIZATION / grid.K)
    if parametrized:
        reg[:m] = 0.0  # the distribution d is fixed by eta^T d = 1; only v needs it
    shooting = CoarseShooting(model, th0, grid.dt, n_heun, T_knots, knot_weights(grid), fw.g0, fw.g1, inputs,
                              reg, check=None if budget is None else budget.check)
    x = ca.MX.sym("p", inputs.n_params)
    if parametrized:
        g = ca.dot(ca.DM(eta), x[:m])  # eta^T d = 1: fixes the scale of (v, d); see the module docstring
        lbg, ubg = [1.0], [1.0]
    else:
        g = ca.MX(0, 1)
        lbg, ubg = [], []
    f_cb, grad_cb, hess_cb = casadi_objective(shooting, int(g.numel()))
    opts = _ipopt_options(max_iter, max_wall_s, ipopt_options)
    opts.update({"grad_f": grad_cb, "hess_lag": hess_cb})
    if budget is not None:  # a cancel (or the spent wall time) ends IPOPT at its next iteration
        opts["iteration_callback"] = stop_when(lambda: budget.over, inputs.n_params, int(g.numel()))
    solver = ca.nlpsol("feedforward", "ipopt", {"x": x, "f": f_cb(x), "g": g}, opts)
    try:
        sol = solver(x0=np.clip(x_init, lbx, ubx), lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    except RuntimeError:  # an exception in a callback (the budget's check) reaches us as CasADi's RuntimeError
        if budget is not None:
            budget.check("the feedforward plan")
        raise
    if budget is not None:
        budget.check("the feedforward plan")  # IPOPT stopped at the wall-time limit, or a cancel came late
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    success = bool(stats.get("success", False))
    iterations = int(stats.get("iter_count", -1))
    xopt = np.asarray(sol["x"], float).ravel()
    if not success and not best_effort:
        raise FeedforwardError(f"feedforward OCP failed: IPOPT status {status} after {iterations} iterations",
                               status)

    t_fine = grid.t_fine
    warm: dict[str, Any] = {"t_knots": grid.t_knots, "parametrized": parametrized, "x": xopt,
                            "n_heun": n_heun, "horizon": horizon, "sweeps": shooting.n_sweeps,
                            "simulations": shooting.n_simulations}
    u_c: Array | None
    v_fine: Array | None
    if parametrized:
        d_opt = np.clip(xopt[:m], 0.0, None)
        v_opt = np.clip(xopt[m:], 0.0, None)
        scale = float(np.max(d_opt))
        u_c = d_opt / scale  # max(u_c) = 1 (20d)
        v_knots = v_opt * scale
        v_fine = np.repeat(v_knots, substeps)  # v held over each OCP interval
        u_ff = saturation(v_fine[:, None] * u_c[None, :])
        warm.update(v=v_knots, u_c=u_c)
    else:
        u_c, v_fine = None, None
        Uk_opt = np.clip(xopt.reshape(grid.K, m), 0.0, 1.0)
        u_ff = np.repeat(Uk_opt, substeps, axis=0)
        warm.update(U=Uk_opt)
    u_ff = limit * u_ff if limit < 1.0 else u_ff
    theta_ref = simulate(real_model, th0, u_ff)
    T_ref = np.asarray(T_ref_fn(t_fine), float)
    T_mean = theta_ref @ np.asarray(model.c_m, float)
    e = T_mean[1:] - T_ref[1:]
    kappa = np.einsum("ij,jk,ik->i", theta_ref[1:], np.asarray(model.W, float), theta_ref[1:])
    objective = float(np.mean(fw.g0 * e**2 + fw.g1 * kappa))
    elapsed = time.perf_counter() - wall0
    plan = FeedforwardPlan(
        t=t_fine, u_ff=u_ff, theta_ref=theta_ref, T_ref=T_ref, T_mean=T_mean, status=status,
        iterations=iterations, solve_s=elapsed, success=success, u_c=u_c, v=v_fine,
        objective=objective, warm=warm,
    )
    log.info(
        "feedforward (%s): %s in %d iterations, %.2f s, horizon %.0f s (%d knots, %d Heun substeps), "
        "max |mean - T_ref| %.2f K",
        "parametrized" if parametrized else "free", status, iterations, elapsed, horizon, grid.K + 1,
        n_heun, plan.max_mean_error,
    )
    return plan


def ocp_seconds(cfg: FurnaceConfig, radiation: Any) -> float:
    """Benchmark ``ocp_s``: wall time (s) of the feedforward plan for a default run (product.md).

    Default scenario (t_E = 120 s, setpoint, beta t_E horizon, t_s), fixed specimen,
    cold start at the configured initial temperature.
    """
    from twin.control.reference import reference_trajectory
    from twin.model.discrete import discrete_model
    from twin.scenario import TransitionReference

    model = discrete_model(cfg, radiation, None)
    theta0 = np.full(model.n, cfg.specimen.initial_temperature)
    ref = reference_trajectory(TransitionReference.model_validate({}), cfg.specimen.initial_temperature)
    t = time.perf_counter()
    plan = solve_feedforward(model, theta0, 0.0, ref, cfg, best_effort=True)
    elapsed = time.perf_counter() - t
    log.info("ocp_s = %.2f s (status %s, %d iterations)", elapsed, plan.status, plan.iterations)
    return elapsed
