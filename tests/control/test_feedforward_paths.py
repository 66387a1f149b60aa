"""The feedforward OCP's other paths (twin.control.feedforward): the power reserve, a failed lamp group, the
warm start, what the plan reports about itself (objective, solve time), the planning budget, bad input.

On the small furnace with a short transition (IPOPT solves of 0.1-1 s), as ``test_feedforward.py``; each
figure is checked against something computed here from the plan's own fields or from the model, not against
the function's output.  The cases are those the mutation run found untested (docs/mutation.md).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from twin.config import small_config
from twin.control.budget import PlanBudget, PlanCancelled, PlanTooLarge
from twin.control.feedforward import solve_feedforward
from twin.control.initial_guess import heating_efficiency
from twin.control.plan import simulate
from twin.control.plan_model import ScaledInputs
from twin.control.reference import reference_trajectory
from twin.scenario import TransitionReference

T0 = 300.0
#: 300 -> 600 K in 30 s: at most 1.5 * 300 / 30 = 15 K/s, half of what the small furnace's lamps give at full
#: power (~30 K/s, test_feedforward.py), so a plan on 80 % of the lamps still tracks it
SETPOINT, T_E, HORIZON = 600.0, 30.0, 36.0


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def model(cfg, small_radiation):
    from twin.model.discrete import discrete_model

    return discrete_model(cfg, small_radiation, None)


@pytest.fixture(scope="module")
def ref():
    return reference_trajectory(TransitionReference(setpoint=SETPOINT, t_E=T_E), T0)


@pytest.fixture(scope="module")
def plan(model, cfg, ref):
    return solve_feedforward(model, np.full(model.n, T0), 0.0, ref, cfg, horizon=HORIZON)


def _mean_error(plan) -> float:
    return float(np.max(np.abs(plan.T_mean - plan.T_ref)))


# ---------------------------------------------------------------- the reserve ([control] feedforward_limit)
def test_a_plan_with_a_reserve_never_asks_more_than_the_limit_and_still_tracks(model, cfg, ref, plan) -> None:
    limited = cfg.with_overrides({"control.feedforward_limit": 0.8})
    p = solve_feedforward(model, np.full(model.n, T0), 0.0, ref, limited, horizon=HORIZON)
    assert p.success, p.status
    assert p.u_ff.max() <= 0.8 + 1e-12  # the reserve: 20 % of every group left to the feedback
    # the heat-up wants full power at the start: some group sits at the limit, not below it
    assert p.u_ff.max() == pytest.approx(0.8, abs=1e-9)
    # the plan's trajectory is the real model (not the scaled one) under the applied inputs (eq. 12a)
    np.testing.assert_allclose(p.theta_ref, simulate(model, p.theta_ref[0], p.u_ff), rtol=1e-12)
    # planned on the furnace seen through 0.8 u', so it tracks as the plan without a reserve does
    # (a plan made for the full lamps and then scaled by 0.8 would lag by tens of kelvin)
    assert _mean_error(p) < 0.01 * SETPOINT
    assert _mean_error(p) < _mean_error(plan) + 0.005 * SETPOINT


# ---------------------------------------------------------------- a failed lamp group
def test_a_failed_group_gets_no_power_and_the_others_carry_the_plan(model, cfg, ref) -> None:
    # the model of a run whose fault detection took group 2 as failed: its column of dF/du is zero
    gains = np.ones(model.m)
    gains[2] = 0.0
    failed = ScaledInputs(model, gains)
    eta = heating_efficiency(failed, np.full(model.n, SETPOINT))
    assert eta[2] == 0.0 and np.all(eta[[0, 1, 3, 4, 5]] > 0.0)
    p = solve_feedforward(failed, np.full(model.n, T0), 0.0, ref, cfg, horizon=HORIZON)
    assert p.success, p.status
    assert p.u_c[2] == 0.0 and np.all(p.u_ff[:, 2] == 0.0)  # d_2 held at 0 by its bound, not left to drift
    assert p.u_c.max() == 1.0 and np.count_nonzero(p.u_c) >= 3
    assert _mean_error(p) < 0.01 * SETPOINT


# ---------------------------------------------------------------- the warm start and the plan's own record
def test_a_free_plan_warm_started_from_the_parametrized_one_reaches_the_cold_starts_optimum(model, cfg, ref,
                                                                                           plan) -> None:
    # Remark 4's free OCP started from the parametrized optimum's inputs against the same OCP from uniform
    # inputs: the same optimum (within IPOPT's acceptable stop).  Not fewer iterations: measured 9 and 9 here
    # (the interior-point method moves the start off the bounds either way), so the warm start is a
    # convenience, not a speed-up, and no test can tell it from a cold one by its result
    theta0 = np.full(model.n, T0)
    warm = solve_feedforward(model, theta0, 0.0, ref, cfg, warm_start=plan, parametrized=False, horizon=HORIZON)
    cold = solve_feedforward(model, theta0, 0.0, ref, cfg, parametrized=False, horizon=HORIZON)
    assert warm.success and cold.success
    assert warm.objective == pytest.approx(cold.objective, rel=0.02)
    assert warm.warm["parametrized"] is False and np.asarray(warm.warm["U"]).shape == (len(plan.warm["v"]), model.m)


def test_the_plan_keeps_its_knots_and_v_for_a_later_warm_start_and_for_v_at(plan, model) -> None:
    w = plan.warm
    assert w["parametrized"] is True and w["horizon"] == pytest.approx(HORIZON)
    tk = np.asarray(w["t_knots"])
    assert tk[0] == 0.0 and np.all(np.diff(tk) > 0) and len(w["v"]) == len(tk) - 1
    # v held over each OCP interval: the fine v is the knots' v repeated (eq. 18's v_j)
    np.testing.assert_array_equal(plan.v_at(plan.t[:-1]), plan.v)
    np.testing.assert_array_equal(np.asarray(w["u_c"]), plan.u_c)
    assert w["n_heun"] >= 1 and w["sweeps"] >= 1 and w["simulations"] >= 1
    # x is IPOPT's (d, v): d over its max is u_c, v times that max is v (the rescaling of (20d))
    x = np.asarray(w["x"])
    d, v = np.clip(x[: model.m], 0.0, None), np.clip(x[model.m:], 0.0, None)
    np.testing.assert_allclose(d / d.max(), plan.u_c, rtol=1e-12)
    np.testing.assert_allclose(v * d.max(), w["v"], rtol=1e-12)


def test_the_objective_is_the_mean_of_eq_20a_over_the_plans_samples(plan, model, cfg) -> None:
    # (20a): g0 (T_mean - T_ref)^2 + g1 theta^T W theta per sample, after the first; from the plan's own fields
    e = plan.T_mean[1:] - plan.T_ref[1:]
    th = plan.theta_ref[1:]
    kappa = np.array([t @ model.W @ t for t in th])
    want = np.mean(cfg.feedforward.g0 * e**2 + cfg.feedforward.g1 * kappa)
    assert plan.objective == pytest.approx(want, rel=1e-10)
    np.testing.assert_allclose(plan.T_ref, [float(v) for v in reference_trajectory(
        TransitionReference(setpoint=SETPOINT, t_E=T_E), T0)(plan.t)], rtol=1e-12)


def test_the_solve_time_is_the_calls_wall_time(model, cfg, ref) -> None:
    t0 = time.perf_counter()
    p = solve_feedforward(model, np.full(model.n, T0), 0.0, ref, cfg, horizon=12.0)
    wall = time.perf_counter() - t0
    assert 0.0 < p.solve_s <= wall and p.solve_s > 0.5 * wall


# ---------------------------------------------------------------- the budget
def test_a_cancelled_budget_stops_the_plan_and_says_which(model, cfg, ref) -> None:
    budget = PlanBudget(max_wall_s=60.0)
    budget.cancel.cancel()
    with pytest.raises(PlanCancelled, match="the feedforward plan was cancelled"):
        solve_feedforward(model, np.full(model.n, T0), 0.0, ref, cfg, horizon=HORIZON, budget=budget)


def test_a_spent_budget_refuses_and_a_generous_one_plans_the_same(model, cfg, ref, plan) -> None:
    spent = PlanBudget(max_wall_s=1.0, started=time.monotonic() - 5.0)
    with pytest.raises(PlanTooLarge, match="the feedforward plan did not finish within 1 s"):
        solve_feedforward(model, np.full(model.n, T0), 0.0, ref, cfg, horizon=HORIZON, budget=spent)
    tiny = PlanBudget(max_wall_s=60.0, max_memory_mb=1e-3)  # the plan's estimate is refused before solving
    with pytest.raises(PlanTooLarge, match="MB"):
        solve_feedforward(model, np.full(model.n, T0), 0.0, ref, cfg, horizon=HORIZON, budget=tiny)
    ok = solve_feedforward(model, np.full(model.n, T0), 0.0, ref, cfg, horizon=HORIZON,
                           budget=PlanBudget(max_wall_s=60.0))
    assert ok.success
    np.testing.assert_array_equal(ok.u_ff, plan.u_ff)  # the budget watches; it does not change the plan


class _SetAfter:
    """A stop flag (a run's stop event) that is set from its ``n``-th look on: a stop that comes while IPOPT
    iterates, after the plan's size was accepted."""

    def __init__(self, n: int) -> None:
        self.n, self.looks = n, 0

    def is_set(self) -> bool:
        self.looks += 1
        return self.looks >= self.n


def test_a_stop_while_ipopt_iterates_ends_the_plan_and_names_it(model, cfg, ref) -> None:
    # the shooting's sweeps look at the budget; the stop raises inside CasADi's callback, which CasADi hands
    # back as a RuntimeError: the budget's own error comes out, naming the plan
    flag = _SetAfter(40)
    budget = PlanBudget.of(60.0, float("inf"), flag)
    with pytest.raises(PlanCancelled, match="^the feedforward plan was cancelled$"):
        solve_feedforward(model, np.full(model.n, T0), 0.0, ref, cfg, horizon=HORIZON, budget=budget)
    assert flag.looks >= 40  # it was the flag, looked at during the solve, that stopped it


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("bad", ["short", "nan", "inf"])
def test_a_start_that_is_not_a_finite_field_is_refused(model, cfg, ref, bad) -> None:
    theta0 = np.full(model.n, T0)
    if bad == "short":
        theta0 = theta0[:-1]
    else:
        theta0[3] = float(bad)
    with pytest.raises(ValueError, match=f"finite vector of {model.n} temperatures"):
        solve_feedforward(model, theta0, 0.0, ref, cfg, horizon=HORIZON)
