"""The plan's model with c_p(T) and the feedforward reserve (twin.control.plan_model, [control])."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.control.feedforward import solve_feedforward
from twin.control.plan_model import CapacityModel, ScaledInputs, plan_model
from twin.control.reference import reference_trajectory
from twin.model.discrete import discrete_model
from twin.physics.materials import Steel
from twin.scenario import TransitionReference


@pytest.fixture(scope="module")
def models(small_radiation):
    cfg = small_config()
    base = discrete_model(cfg, small_radiation)
    return cfg, base, CapacityModel.of(base, cfg)


def test_rates_are_the_energy_balance_with_c_p_of_t(models):
    """Node i: c_p(theta_i) dtheta_i/dt = c_bar f_i (the same heat flow into a capacity that follows the
    table); checked against the table itself, not the scaling helper."""
    cfg, base, model = models
    steel = Steel.from_config(cfg)
    theta = np.linspace(320.0, 1080.0, base.n)
    u = np.linspace(0.1, 0.9, base.m)
    np.testing.assert_allclose(steel.heat_capacity(theta) * model.rhs(theta, u),
                               base.fe.heat_capacity * base.rhs(theta, u), rtol=1e-12)
    # the steady state does not depend on the capacity
    th = base.steady_state(np.full(base.m, 0.5))
    assert np.max(np.abs(model.rhs(th, np.full(base.m, 0.5)))) < 1e-6


def test_jacobians_match_finite_differences(models):
    """dF/dtheta (product rule on D f) and dF/du against central differences of step()."""
    _, base, model = models
    rng = np.random.default_rng(1)
    theta = 700.0 + 200.0 * rng.random(base.n)  # across the table's segments
    u = rng.random(base.m)
    J = model.jac_theta(theta, u)
    G = model.jac_u(theta, u)
    h = 1e-3
    for i in rng.choice(base.n, 6, replace=False):
        d = np.zeros(base.n)
        d[i] = h
        fd = (model.step(theta + d, u) - model.step(theta - d, u)) / (2 * h)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-9)
    for i in range(base.m):
        d = np.zeros(base.m)
        d[i] = h
        fd = (model.step(theta, u + d) - model.step(theta, u - d)) / (2 * h)
        np.testing.assert_allclose(G[:, i], fd, rtol=1e-7, atol=1e-10)


def test_scaled_inputs_are_the_model_at_scaled_power(models):
    _, base, _ = models
    s = ScaledInputs(base, 0.8)
    theta, u = np.full(base.n, 600.0), np.full(base.m, 0.5)
    np.testing.assert_allclose(s.step(theta, u), base.step(theta, 0.4 * np.ones(base.m)))
    np.testing.assert_allclose(s.jac_u(theta, u), 0.8 * base.jac_u(theta, u))


def test_plan_model_follows_the_setting(models):
    cfg, base, _ = models
    assert plan_model(base, cfg) is base
    temp = cfg.with_overrides({"control.plan_heat_capacity": "temperature"})
    assert isinstance(plan_model(base, temp), CapacityModel)


def test_reserve_caps_the_feedforward(models):
    """feedforward_limit = 0.8: no group's u_ff above 0.8 u_max; theta_ref is the real model under u_ff."""
    cfg, base, _ = models
    ref = reference_trajectory(TransitionReference(setpoint=1000.0, t_E=20.0), 300.0)
    theta0 = np.full(base.n, 300.0)
    free = solve_feedforward(base, theta0, 0.0, ref, cfg)
    assert free.u_ff.max() > 0.95  # the heat-up wants full power somewhere
    capped_cfg = cfg.with_overrides({"control.feedforward_limit": 0.8})
    plan = solve_feedforward(base, theta0, 0.0, ref, capped_cfg)
    assert plan.success and plan.u_ff.max() <= 0.8 + 1e-12
    th = theta0
    for j in range(50):
        th = base.step(th, plan.u_ff[j])
    np.testing.assert_allclose(plan.theta_ref[50], th, rtol=1e-12)
