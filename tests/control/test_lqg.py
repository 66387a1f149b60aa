"""LQG feedback (twin.control.lqg): DARE, Riccati recursion, controller and anti-windup."""

from __future__ import annotations

import time

import numpy as np
import pytest
import scipy.linalg
from controller_standin import make_standin

from twin.config import small_config
from twin.control.lqg import (
    Controller,
    Gains,
    IntegratorState,
    RiccatiError,
    anti_windup_delta,
    augmented_system,
    dare,
    feedback_control,
    integrator_delta,
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
    assert new.model is standin and new.cfg is cfg  # the model is kept unless a new one is given


def test_with_plan_switches_plan_gains_and_model_and_keeps_a_frozen_integrator(standin, cfg):
    ctrl, plan, _ = _controller(standin, cfg, 0.98)
    for j in range(3):
        ctrl.control(j, plan.theta_ref[0] - 50.0)  # saturated: the integrator freezes (see above)
    assert ctrl.state.frozen
    other = make_standin(gain_scale=0.8)
    new_plan = _constant_plan(other, np.full(other.m, 0.5), 30)
    new_gains = lqg_gains(other, new_plan, cfg)
    new = ctrl.with_plan(new_plan, new_gains, other)
    assert new.model is other and new.plan is new_plan and new.gains is new_gains and new.cfg is cfg
    assert new.state.frozen and new.state.e_I == ctrl.state.e_I
    theta_hat = new_plan.theta_ref[2] + 0.3
    u, u_ff, du = new.control(2, theta_hat)
    out, _ = feedback_control(new_gains, new_plan, other.c_m, cfg.lqg.delta0, 2, theta_hat,
                              IntegratorState(ctrl.state.e_I, True))
    np.testing.assert_array_equal(u, out.u)
    np.testing.assert_array_equal(du, out.du)


def test_control_at_a_run_time_uses_the_sample_of_the_plan(standin, cfg):
    ctrl, plan, gains = _controller(standin, cfg, 0.5)
    theta_hat = plan.theta_ref[7] + 0.5
    u, _, du = ctrl.control_at(0.69, theta_hat)  # 0.69 s / 0.1 s rounds to sample 7
    e = np.append(theta_hat - plan.theta_ref[7], 0.0)
    np.testing.assert_allclose(du, gains.K[7] @ e, rtol=1e-12)
    assert ctrl.last is not None and ctrl.last.u is not None and np.array_equal(ctrl.last.u, u)


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


# ------------------------------------------------------------------ anti-windup at its edges
# Remark 5: delta = 0 iff 1^T u > delta0 (strictly); the clamp rule: delta = 0 iff no group can follow
# the integrator's push (sign of k_int * e): at u = 1 while pushed up, at u = 0 while pushed down.
ONE_ULP_ABOVE_2 = np.nextafter(2.0, 3.0)


@pytest.mark.parametrize(
    ("u", "delta"),
    [([0.5, 0.5, 1.0], 1.0), ([0.5, 0.5, ONE_ULP_ABOVE_2 - 1.0], 0.0), ([0.5, 0.5, 0.9], 1.0), ([1.0, 1.0, 1.0], 0.0)],
    ids=["sum-at-delta0", "sum-above", "sum-below", "all-full"],
)
def test_remark5_total_power_threshold(u, delta) -> None:
    u = np.array(u)
    assert anti_windup_delta(u, 2.0) == delta
    # the controller's rule applies the same threshold to the applied (clipped) input; a 1 K error
    # pushed upwards by a group below 1 would otherwise keep the integrator running
    assert integrator_delta(u, u - 0.01, np.array([1.0, 1.0, 1.0]), -1.0, 2.0) == delta


@pytest.mark.parametrize(
    ("u_raw", "k_int", "error", "delta"),
    [
        ([1.0, 1.0], [-1.0, -1.0], -1.0, 0.0),  # too cold, pushed up, both at exactly 1: frozen
        ([1.0, np.nextafter(1.0, 0.0)], [-1.0, -1.0], -1.0, 1.0),  # one ulp below 1: that group follows
        ([1.3, 0.99], [-1.0, -1.0], -1.0, 1.0),  # one group clipped, the other can follow
        ([1.3, 1.1], [-1.0, 0.0], -1.0, 0.0),  # the free group is not pushed (k_int = 0)
        ([1.3, 0.5], [-1.0, 0.0], -1.0, 0.0),  # nor is a group in the middle of its range that k_int ignores
        ([-0.3, 0.5], [-1.0, 0.0], 1.0, 0.0),  # the same, pushed down with the pushed group at 0
        ([1.3, 1.1], [-1.0, -1.0], 1.0, 1.0),  # too hot: pushed down, groups at 1 can follow
        ([0.0, 0.0], [-1.0, -1.0], 1.0, 0.0),  # too hot, both at exactly 0: frozen
        ([0.0, np.nextafter(0.0, 1.0)], [-1.0, -1.0], 1.0, 1.0),  # one ulp above 0 follows
        ([-0.2, -0.1], [-1.0, -1.0], -1.0, 1.0),  # below 0 but pushed up: can follow
        ([-0.2, -0.1], [1.0, 1.0], -1.0, 0.0),  # k_int > 0: a cold error pushes down, both at 0: frozen
        ([1.3, 1.1], [-1.0, -1.0], 0.0, 1.0),  # no error: nothing to integrate, never frozen
    ],
)
def test_clamp_rule_at_the_input_bounds(u_raw, k_int, error, delta) -> None:
    u_raw = np.array(u_raw)
    u = np.clip(u_raw, 0.0, 1.0)
    assert integrator_delta(u, u_raw, np.array(k_int), error, 10.0) == delta  # delta0 out of reach


def _one_step(standin, cfg, u_level, offset, delta0, e_I=0.0):
    plan = _constant_plan(standin, np.full(standin.m, u_level), 5)
    gains = lqg_gains(standin, plan, cfg)
    out, new = feedback_control(gains, plan, standin.c_m, delta0, 0, plan.theta_ref[0] + offset,
                                IntegratorState(e_I))
    return plan, gains, out, new


def test_feedback_control_integrates_exactly_at_the_threshold_and_freezes_above(standin, cfg) -> None:
    # a 0.5 K error: no group is clipped, so only Remark 5 decides; the applied sum is the threshold
    plan, gains, out, new = _one_step(standin, cfg, 0.6, -0.5, 10.0, e_I=3.0)
    total = float(out.u.sum())
    _, _, at, at_new = _one_step(standin, cfg, 0.6, -0.5, total, e_I=3.0)
    assert at.delta == 1.0 and at_new.e_I == pytest.approx(3.0 + plan.t_s * at.mean_error, rel=1e-12)
    assert at.mean_error == pytest.approx(-0.5, rel=1e-9) and not at_new.frozen
    _, _, above, above_new = _one_step(standin, cfg, 0.6, -0.5, np.nextafter(total, 0.0), e_I=3.0)
    assert above.delta == 0.0 and above_new.e_I == 3.0 and above_new.frozen
    # the integrator state enters the feedback: Delta u = K_j [theta_hat - theta_ref; e_I] (eq. 25)
    np.testing.assert_allclose(above.du, gains.K[0] @ np.append(np.full(standin.n, -0.5), 3.0), rtol=1e-12)


@pytest.mark.parametrize("every", [1, 3])
def test_gains_use_delta_of_the_feedforward_at_every_sample(standin, cfg, every) -> None:
    """The recursion (26), (29) with delta(u_ff,j) of Remark 5 in Phi~_j (24), written out here.

    u_ff alternates between a total above and below delta0; Phi_j, Gamma_j are held over 3 samples
    (jacobian_every = 3), so the design must switch delta inside a hold.
    """
    N = 12
    c = small_config().with_overrides({"lqg.delta0": 1.5})
    u_lo, u_hi = np.full(standin.m, 0.4), np.full(standin.m, 0.6)  # totals 1.2 and 1.8 around 1.5
    u_ff = np.array([u_hi if j % 2 else u_lo for j in range(N)])
    theta = [steady_state(standin, u_lo, np.full(standin.n, 900.0))]
    for j in range(N):
        theta.append(standin.step(theta[-1], u_ff[j]))
    theta = np.array(theta)
    T = theta @ standin.c_m
    plan = FeedforwardPlan(np.arange(N + 1) * standin.t_s, u_ff, theta, T, T, "alternating", 0, 0.0, True)
    t0 = time.perf_counter()
    gains = lqg_gains(standin, plan, c, jacobian_every=every)
    assert gains.jacobian_every == every and 0.0 < gains.design_s <= time.perf_counter() - t0

    w = c.lqg
    Q = weight_matrix(standin.c_m, w.q0, w.q1)
    Pt_N, Gt_N = augmented_system(standin.jac_theta(theta[N], u_ff[-1]), standin.jac_u(theta[N], u_ff[-1]),
                                  standin.c_m, standin.t_s, 1.0)  # terminal design: delta = 1
    P = dare(Pt_N, Gt_N, Q, w.r0)
    np.testing.assert_allclose(gains.P_terminal, P, rtol=1e-12)
    expected = np.empty_like(gains.K)
    for j in range(N - 1, -1, -1):
        jj = (j // every) * every
        delta = 0.0 if u_ff[j].sum() > 1.5 else 1.0
        Pt, Gt = augmented_system(standin.jac_theta(theta[jj], u_ff[jj]), standin.jac_u(theta[jj], u_ff[jj]),
                                  standin.c_m, standin.t_s, delta)
        P, expected[j] = riccati_step(P, Pt, Gt, Q, w.r0)
    np.testing.assert_allclose(gains.K, expected, rtol=1e-10, atol=1e-14 * np.abs(expected).max())
    if every == 1:  # the default is a Jacobian at every sample
        np.testing.assert_array_equal(lqg_gains(standin, plan, c).K, gains.K)
    # delta matters: with the integrator row switched off the integral gain changes
    assert np.abs(gains.K[1][:, -1] - gains.K[0][:, -1]).max() > 1e-6 * np.abs(gains.K[0][:, -1]).max()


def test_gain_lookup_beyond_the_plan_is_the_terminal_gain() -> None:
    K = np.arange(3.0)[:, None, None] * np.ones((3, 2, 4))
    gains = Gains(K, np.full((2, 4), 9.0), np.eye(4))
    assert gains.at(0)[0, 0] == 0.0 and gains.at(2)[0, 0] == 2.0
    assert gains.at(3)[0, 0] == 9.0 and gains.at(-1)[0, 0] == 9.0 and gains.jacobian_every == 1


def test_dare_without_a_stabilising_solution_raises() -> None:
    # x+ = 2 x, and the input cannot act on it (B = 0): no feedback stabilises it
    with pytest.raises(RiccatiError), np.errstate(over="ignore", invalid="ignore"):  # the iterates blow up
        dare(np.array([[2.0]]), np.array([[0.0]]), np.array([[1.0]]), 1.0)
