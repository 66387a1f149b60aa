"""LQG feedback (twin.control.lqg): DARE, Riccati recursion, controller and anti-windup."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from controller_standin import make_standin

from twin.config import small_config
from twin.control.lqg import (
    Controller,
    IntegratorState,
    augmented_system,
    dare,
    lqg_gains,
    riccati_step,
    weight_matrix,
)
from twin.control.plan import FeedforwardPlan
from twin.control.reference import steady_state


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def standin():
    return make_standin()


def _constant_plan(model, u, n_steps):
    """A plan that sits at the model's steady state for ``u`` (theta_ref constant)."""
    theta = steady_state(model, u, np.full(model.n, 900.0))
    T = float(model.c_m @ theta)
    t = np.arange(n_steps + 1) * model.t_s
    return FeedforwardPlan(
        t=t,
        u_ff=np.tile(u, (n_steps, 1)),
        theta_ref=np.tile(theta, (n_steps + 1, 1)),
        T_ref=np.full(n_steps + 1, T),
        T_mean=np.full(n_steps + 1, T),
        status="constant",
        iterations=0,
        solve_s=0.0,
        success=True,
    )


def _augmented_at_steady(model, cfg, u):
    theta = steady_state(model, u, np.full(model.n, 900.0))
    Pt, Gt = augmented_system(model.jac_theta(theta, u), model.jac_u(theta, u), model.c_m, model.t_s, 1.0)
    Q = weight_matrix(model.c_m, cfg.lqg.q0, cfg.lqg.q1)
    return Pt, Gt, Q


def test_weight_matrix_is_eq28(standin):
    Q = weight_matrix(standin.c_m, 2.0, 3.0)
    e = np.random.default_rng(0).normal(size=standin.n + 1)
    # eq. (28): e^T Q e = q0 (c_m^T e_theta)^2 + q1 e_I^2, exact up to round-off
    expected = 2.0 * float(standin.c_m @ e[:-1]) ** 2 + 3.0 * e[-1] ** 2
    assert e @ Q @ e == pytest.approx(expected, rel=1e-12)


def test_dare_scalar_closed_form():
    # P = q + a^2 P - a^2 P^2 b^2 / (r + b^2 P): the positive root of b^2 P^2 + (r(1 - a^2) - q b^2) P - q r = 0
    a, b, q, r = 0.95, 0.3, 2.0, 0.5
    A = b**2
    Bq = r * (1 - a**2) - q * b**2
    P_exact = (-Bq + np.sqrt(Bq**2 + 4 * A * q * r)) / (2 * A)
    P = dare(np.array([[a]]), np.array([[b]]), np.array([[q]]), r)
    assert P[0, 0] == pytest.approx(P_exact, rel=1e-12)  # closed form; doubling converges to round-off


def test_terminal_dare_matches_scipy_and_dlqr(standin, cfg):
    control = pytest.importorskip("control")
    u = np.full(standin.m, 0.5)
    Pt, Gt, Q = _augmented_at_steady(standin, cfg, u)
    r0 = cfg.lqg.r0
    P = dare(Pt, Gt, Q, r0)
    P_sp = scipy.linalg.solve_discrete_are(Pt, Gt, Q, r0 * np.eye(standin.m))
    # brief: the terminal gain equals the scipy / python-control solution to 1e-8 (relative)
    assert np.max(np.abs(P - P_sp)) <= 1e-8 * np.max(np.abs(P_sp))
    K_dlqr, S_dlqr, _ = control.dlqr(Pt, Gt, Q, r0 * np.eye(standin.m))
    plan = _constant_plan(standin, u, 10)
    gains = lqg_gains(standin, plan, cfg)
    # dlqr returns u = -K x; ours is Delta u = K e (eq. 25)
    assert np.max(np.abs(gains.K_terminal + K_dlqr)) <= 1e-8 * np.max(np.abs(K_dlqr))
    assert np.max(np.abs(gains.P_terminal - S_dlqr)) <= 1e-8 * np.max(np.abs(S_dlqr))


def test_terminal_dare_on_the_furnace_model_matches_scipy_and_dlqr(cfg, small_radiation):
    """The real augmented system (eq. 24) at a steady state: eigenvalues close to 1."""
    control = pytest.importorskip("control")
    from twin.model.discrete import discrete_model

    model = discrete_model(cfg, small_radiation, None)
    u = np.full(model.m, 0.5)
    theta = steady_state(model, u, np.full(model.n, 1000.0))
    Pt, Gt, Q = _augmented_at_steady(model, cfg, u)
    plan = FeedforwardPlan(np.arange(3) * model.t_s, np.tile(u, (2, 1)), np.tile(theta, (3, 1)),
                           np.full(3, model.c_m @ theta), np.full(3, model.c_m @ theta), "steady", 0, 0.0, True)
    gains = lqg_gains(model, plan, cfg)
    r0 = cfg.lqg.r0 * np.eye(model.m)
    P_sp = scipy.linalg.solve_discrete_are(Pt, Gt, Q, r0)
    K_dlqr, _, _ = control.dlqr(Pt, Gt, Q, r0)
    # brief: equal to the scipy / python-control solution to 1e-8 (relative)
    assert np.max(np.abs(gains.P_terminal - P_sp)) <= 1e-8 * np.max(np.abs(P_sp))
    assert np.max(np.abs(gains.K_terminal + K_dlqr)) <= 1e-8 * np.max(np.abs(K_dlqr))


def test_dare_residual_is_zero(standin, cfg):
    Pt, Gt, Q = _augmented_at_steady(standin, cfg, np.full(standin.m, 0.4))
    r0 = cfg.lqg.r0
    P = dare(Pt, Gt, Q, r0)
    S = r0 * np.eye(standin.m) + Gt.T @ P @ Gt
    res = Q + Pt.T @ P @ Pt - Pt.T @ P @ Gt @ np.linalg.solve(S, Gt.T @ P @ Pt) - P
    # the DARE itself (end of section 4.2); 1e-10 of |P| is round-off for ~25 states
    assert np.max(np.abs(res)) <= 1e-10 * np.max(np.abs(P))
    K = -np.linalg.solve(S, Gt.T @ P @ Pt)
    # stabilizing solution: closed-loop spectral radius below 1
    assert np.max(np.abs(np.linalg.eigvals(Pt + Gt @ K))) < 1.0


def test_recursion_on_constant_system_converges_to_terminal_gain(standin, cfg):
    plan = _constant_plan(standin, np.full(standin.m, 0.5), 3000)
    gains = lqg_gains(standin, plan, cfg)
    # last step starts from P_S itself, so K_{N-1} is the terminal gain up to round-off
    assert np.max(np.abs(gains.K[-1] - gains.K_terminal)) <= 1e-9 * np.max(np.abs(gains.K_terminal))
    # P_S is a fixed point of (29): any horizon gives the same gains on a constant system
    assert np.max(np.abs(gains.K[0] - gains.K_terminal)) <= 1e-8 * np.max(np.abs(gains.K_terminal))


def test_recursion_from_zero_converges_to_dare(standin, cfg):
    # independent check of (26), (29): iterate from P = 0 (no terminal cost) until stationary
    Pt, Gt, Q = _augmented_at_steady(standin, cfg, np.full(standin.m, 0.5))
    r0 = cfg.lqg.r0
    P = np.zeros_like(Q)
    for _ in range(20000):
        P, K = riccati_step(P, Pt, Gt, Q, r0)
    P_s = dare(Pt, Gt, Q, r0)
    # the value iteration converges geometrically (closed-loop radius^2 per step); 20000 steps
    # leave far less than 1e-6 relative
    assert np.max(np.abs(P - P_s)) <= 1e-6 * np.max(np.abs(P_s))


def test_jacobian_hold_changes_gains_little_on_slow_plan(standin, cfg):
    # a slowly varying plan: ramp of u over 60 s; holding Phi for 1 s changes K by < 2 %
    N = 600
    plan0 = _constant_plan(standin, np.full(standin.m, 0.5), N)
    u_ff = np.linspace(0.3, 0.6, N)[:, None] * np.ones(standin.m)
    theta = [plan0.theta_ref[0]]
    for j in range(N):
        theta.append(standin.step(theta[-1], u_ff[j]))
    theta = np.array(theta)
    T = theta @ standin.c_m
    plan = FeedforwardPlan(plan0.t, u_ff, theta, T, T, "ramp", 0, 0.0, True)
    g1 = lqg_gains(standin, plan, cfg, jacobian_every=1)
    g10 = lqg_gains(standin, plan, cfg, jacobian_every=10)
    rel = np.max(np.abs(g1.K - g10.K)) / np.max(np.abs(g1.K))
    # the state changes by < 1 K per 1 s hold, the T^3 slope by < 0.5 % -> gains by far less than 2 %
    assert rel < 0.02


def _controller(standin, cfg, u_level, n_steps=50):
    plan = _constant_plan(standin, np.full(standin.m, u_level), n_steps)
    gains = lqg_gains(standin, plan, cfg)
    return Controller(standin, plan, gains, cfg), plan, gains


def test_control_is_eq17_25_and_integrator_eq22(standin, cfg):
    ctrl, plan, gains = _controller(standin, cfg, 0.5)
    theta_hat = plan.theta_ref[0] - 2.0  # 2 K too cold everywhere: small correction, no clipping
    u, u_ff, du = ctrl.control(0, theta_hat)
    e = np.append(theta_hat - plan.theta_ref[0], 0.0)
    np.testing.assert_allclose(du, gains.K[0] @ e, rtol=1e-12)
    np.testing.assert_allclose(u, u_ff + du, rtol=1e-12)
    assert np.all(du > 0)  # colder than planned -> more power
    # eq. (22): e_I,1 = e_I,0 + t_s e_0 with e_0 = c_m^T theta_hat - T_ref,0 = -2 K
    assert ctrl.state.e_I == pytest.approx(standin.t_s * -2.0, rel=1e-12)
    assert not ctrl.state.frozen
    u2, _, du2 = ctrl.control(1, theta_hat)
    e2 = np.append(theta_hat - plan.theta_ref[1], -0.2)
    np.testing.assert_allclose(du2, gains.K[1] @ e2, rtol=1e-12)


def test_anti_windup_freezes_integrator_at_upper_saturation(standin, cfg):
    ctrl, plan, _ = _controller(standin, cfg, 0.98)
    theta_hat = plan.theta_ref[0] - 50.0  # far too cold: the correction pushes u above 1
    for j in range(20):
        u, u_ff, du = ctrl.control(j, theta_hat)
        assert np.all(u <= 1.0) and np.any(u_ff + du > 1.0)
    assert ctrl.state.e_I == 0.0 and ctrl.state.frozen


def test_integrator_keeps_running_while_another_group_can_follow(standin, cfg):
    # group 2 runs at u = 1 in the plan; the plant is too cold, so the integrator pushes all groups up:
    # groups 0 and 1 can still follow, so e_I must integrate (eq. 22 with delta = 1)
    plan = _constant_plan(standin, np.array([0.4, 0.4, 1.0]), 20)
    ctrl = Controller(standin, plan, lqg_gains(standin, plan, cfg), cfg)
    u, u_ff, du = ctrl.control(0, plan.theta_ref[0] - 2.0)
    assert u[2] == 1.0 and du[2] > 0 and np.all(u[:2] < 1.0)
    assert ctrl.state.e_I == pytest.approx(standin.t_s * -2.0, rel=1e-12) and not ctrl.state.frozen


def test_anti_windup_freezes_integrator_on_total_power(standin, cfg):
    # Remark 5: delta = 0 when 1^T u > delta0; u = 0.9 in each of 3 groups -> 2.7
    ctrl, plan, _ = _controller(standin, cfg.with_overrides({"lqg.delta0": 2.5}), 0.9)
    ctrl.control(0, plan.theta_ref[0] - 0.5)  # small error: no clipping, only the sum rule applies
    assert ctrl.state.e_I == 0.0 and ctrl.state.frozen


def test_unused_group_at_zero_does_not_freeze_integrator(standin, cfg):
    plan = _constant_plan(standin, np.array([0.0, 0.6, 0.6]), 20)
    ctrl = Controller(standin, plan, lqg_gains(standin, plan, cfg), cfg)
    theta_hat = plan.theta_ref[0] + 3.0  # too hot: group 0 (off in the plan) is pushed below 0
    u, u_ff, du = ctrl.control(0, theta_hat)
    assert u[0] == 0.0 and du[0] < 0
    assert ctrl.state.e_I == pytest.approx(standin.t_s * 3.0, rel=1e-12)


def test_terminal_gain_used_beyond_horizon(standin, cfg):
    ctrl, plan, gains = _controller(standin, cfg, 0.5, n_steps=5)
    theta_hat = plan.theta_ref[-1] + 1.0
    _, _, du = ctrl.control(40, theta_hat)
    e = np.append(theta_hat - plan.theta_ref[-1], 0.0)
    np.testing.assert_allclose(du, gains.K_terminal @ e, rtol=1e-12)


def test_with_plan_keeps_integrator(standin, cfg):
    ctrl, plan, gains = _controller(standin, cfg, 0.5)
    ctrl.control(0, plan.theta_ref[0] - 1.0)
    new = ctrl.with_plan(plan, gains)
    assert new.state.e_I == ctrl.state.e_I and new.state is not ctrl.state


def test_integral_action_removes_steady_mean_error_under_mismatch(standin, cfg):
    """Closed loop on a plant with 10 % weaker heaters than the model, state known exactly."""
    plant = make_standin(gain_scale=0.9)
    ctrl, plan, _ = _controller(standin, cfg, 0.5, n_steps=10)
    theta = plan.theta_ref[0].copy()
    T_ref = plan.T_ref[0]
    errors = []
    for j in range(6000):  # 600 s, about 60 mean time constants of the stand-in (~10 s)
        u, _, _ = ctrl.control(j, theta)
        theta = plant.step(theta, u)
        errors.append(float(standin.c_m @ theta) - T_ref)
    # without integral action the 10 % gain loss leaves tens of K (tested below); with it the
    # error decays to zero: after 60 time constants 0.05 K is a generous bound
    assert abs(errors[-1]) < 0.05
    assert not ctrl.state.frozen
    # the same loop without the integrator state update (e_I held at 0) keeps an offset
    ctrl2, _, _ = _controller(standin, cfg, 0.5, n_steps=10)
    theta = plan.theta_ref[0].copy()
    for j in range(6000):
        ctrl2.state = IntegratorState(0.0)
        u, _, _ = ctrl2.control(j, theta)
        theta = plant.step(theta, u)
    assert abs(float(standin.c_m @ theta) - T_ref) > 1.0
