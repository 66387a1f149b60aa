"""Re-planning during a run (twin.control.replan): new reference, oscillation switch, warm start."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.control.feedforward import solve_feedforward
from twin.control.initial_guess import KnotGrid, heating_efficiency, parametrized_guess
from twin.control.lqg import Controller
from twin.control.reference import reference_trajectory
from twin.control.replan import replan
from twin.scenario import OscillationSpec, TransitionReference

T0 = 300.0  # cold start (K)


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def model(cfg, small_radiation):
    from twin.model.discrete import discrete_model

    return discrete_model(cfg, small_radiation, None)


@pytest.fixture(scope="module")
def first(model, cfg):
    """The run's first plan: 300 K -> 700 K in 20 s, horizon beta t_E = 24 s."""
    ref = reference_trajectory(TransitionReference(setpoint=700.0, t_E=20.0), T0)
    return replan(model, cfg, np.full(model.n, T0), 0.0, ref, None, horizon=24.0)


def test_first_plan_and_gains_cover_the_horizon(first, model):
    plan, gains = first
    assert plan.success and plan.t[0] == 0.0 and plan.n_steps == 240
    assert gains.K.shape == (240, model.m, model.n + 1) and gains.K_terminal.shape == (model.m, model.n + 1)


def test_replan_after_a_reference_change(first, model, cfg):
    plan0, gains0 = first
    t_now = 10.0
    j = plan0.index_at(t_now)
    theta_hat = plan0.theta_ref[j] + 3.0  # the estimate need not lie on the old plan
    T_now = float(model.c_m @ theta_hat)
    ref = reference_trajectory(TransitionReference(setpoint=600.0, t_E=10.0), T_now, t_start=t_now)
    plan, gains = replan(model, cfg, theta_hat, t_now, ref, plan0, horizon=12.0)
    assert plan.success, plan.status
    assert plan.t[0] == t_now and plan.n_steps == 120 and gains.K.shape[0] == 120
    np.testing.assert_array_equal(plan.theta_ref[0], theta_hat)  # (20c): from the current estimate
    np.testing.assert_allclose(plan.T_ref, ref(plan.t), rtol=0, atol=0)
    e = plan.T_mean - plan.T_ref
    j_E = plan.index_at(20.0)
    # the paper's closed-loop figures (section 5.1) as the bar for the nominal plan:
    # |mean error| < 2 % of the setpoint in the transition, < 0.5 % once it is constant
    assert np.max(np.abs(e[: j_E + 1])) < 0.02 * 600.0
    assert np.max(np.abs(e[j_E:])) < 0.005 * 600.0


def test_controller_keeps_its_integrator_across_a_replan(first, model, cfg):
    plan0, gains0 = first
    ctrl = Controller(model, plan0, gains0, cfg)
    for j in range(5):
        ctrl.control(j, plan0.theta_ref[j] - 1.0)  # 1 K too cold: e_I integrates (eq. 22)
    e_I = ctrl.state.e_I
    assert e_I < 0
    ref = reference_trajectory(TransitionReference(setpoint=650.0, t_E=10.0),
                               float(model.c_m @ plan0.theta_ref[5]), t_start=0.5)
    plan, gains = replan(model, cfg, plan0.theta_ref[5], 0.5, ref, plan0, horizon=12.0)
    new = ctrl.with_plan(plan, gains)
    assert new.state.e_I == e_I and new.plan is plan
    u, u_ff, _ = new.control(0, plan.theta_ref[0])
    np.testing.assert_array_equal(u_ff, plan.u_ff[0])


def test_oscillation_switch_replans_on_the_averaged_model(first, model, cfg, small_radiation):
    from twin.model.discrete import discrete_model

    plan0, _ = first
    osc = discrete_model(cfg, small_radiation, OscillationSpec(enabled=True, amplitude=0.048, period=18.0))
    theta_hat = plan0.theta_ref[-1]
    ref = lambda t: np.full_like(np.asarray(t, float), 700.0)  # noqa: E731  (constant after the transition)
    plan, gains = replan(osc, cfg, theta_hat, 24.0, ref, plan0, horizon=12.0)
    assert plan.success, plan.status
    # the averaged model (eq. 11) moves the steady power distribution: the plan must differ
    assert np.max(np.abs(plan.u_ff[-1] - plan0.u_ff[-1])) > 1e-3
    # and still hold the mean: < 0.5 % of the setpoint (paper, steady state)
    assert np.max(np.abs(plan.T_mean - 700.0)) < 0.005 * 700.0


def test_warm_start_keeps_the_previous_distribution(first, model):
    plan0, _ = first
    grid = KnotGrid(10.0, model.t_s, 10, 12)
    eta = heating_efficiency(model, np.full(model.n, 700.0))
    T_knots = np.full(grid.K + 1, 650.0)
    x = parametrized_guess(model, grid, 1, T_knots, plan0.theta_ref[100], plan0, eta, 0.01)
    d = x[: model.m]
    expected = np.maximum(plan0.u_c, 0.05)  # WARM_FLOOR keeps the start off the bounds
    np.testing.assert_allclose(d, expected / (eta @ expected), rtol=1e-12)
    assert eta @ d == pytest.approx(1.0, rel=1e-12)


def test_free_replan_from_a_parametrized_plan(first, model, cfg):
    plan0, _ = first
    ref = reference_trajectory(TransitionReference(setpoint=700.0, t_E=20.0), T0)
    plan, gains = replan(model, cfg, np.full(model.n, T0), 0.0, ref, plan0, parametrized=False, horizon=24.0)
    assert plan.success and plan.u_c is None and gains.K.shape[0] == plan.n_steps
    # Remark 4: started from the parametrized plan, the free plan is at least as good
    # (1e-3 relative slack for the smoothed saturation of the parametrized OCP)
    assert plan.objective <= plan0.objective * (1.0 + 1e-3)


def test_replan_failure_raises_with_status(model, cfg):
    from twin.control.plan import FeedforwardError

    ref = reference_trajectory(TransitionReference(setpoint=700.0, t_E=20.0), T0)
    with pytest.raises(FeedforwardError, match="IPOPT status"):
        solve_feedforward(model, np.full(model.n, T0), 0.0, ref, cfg, max_iter=0, horizon=24.0)
