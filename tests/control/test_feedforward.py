"""Feedforward OCP (twin.control.feedforward, twin.control.shooting): derivatives, constraints, tracking, failures."""

from __future__ import annotations

import numpy as np
import pytest
from controller_standin import make_standin

from twin.config import small_config
from twin.control.feedforward import solve_feedforward
from twin.control.initial_guess import heating_efficiency
from twin.control.ocp_grid import transition_end
from twin.control.plan import FeedforwardError, simulate
from twin.control.reference import reference_trajectory
from twin.control.shooting import CoarseShooting, FreeInputs, ScaledDistribution, smooth_min1
from twin.scenario import TransitionReference

T0 = 300.0  # cold start of the default furnace (K)


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def model(cfg, small_radiation):
    from twin.model.discrete import discrete_model

    return discrete_model(cfg, small_radiation, None)


@pytest.fixture(scope="module")
def short_ref():
    # a short transition keeps the OCP small (24 intervals of 1 s); 400 K in 20 s needs at most
    # 1.5 * 400 / 20 = 30 K/s, and the furnace heats its cold fillet at ~30 K/s at full power
    return reference_trajectory(TransitionReference(setpoint=700.0, t_E=20.0), T0)


#: beta t_E of the paper's horizon rule for the short transition (1.2 * 20 s)
HORIZON = 24.0
#: no early "acceptable" stop: the KKT test below wants IPOPT's strict convergence
STRICT = {"ipopt.acceptable_iter": 10**6}


@pytest.fixture(scope="module")
def plan(model, cfg, short_ref):
    return solve_feedforward(model, np.full(model.n, T0), 0.0, short_ref, cfg, horizon=HORIZON,
                             ipopt_options=STRICT)


# ---------------------------------------------------------------- shooting derivatives
def _shooting(model, inputs, K, T_knots, reg=None):
    w = np.full(K, 1.0 / K)
    return CoarseShooting(model, np.full(model.n, T0), 1.0, 1, T_knots, w, 100.0, 1.0, inputs, reg)


def _fd_grad(sh, p, eps):
    g = np.zeros_like(p)
    for i in range(p.size):
        dp = np.zeros_like(p)
        dp[i] = eps
        g[i] = (sh.simulate(p + dp)[0] - sh.simulate(p - dp)[0]) / (2 * eps)
    return g


def _fd_hess(sh, p, eps):
    H = np.zeros((p.size, p.size))
    for i in range(p.size):
        dp = np.zeros_like(p)
        dp[i] = eps
        H[:, i] = (sh.sweep(p + dp).grad - sh.sweep(p - dp).grad) / (2 * eps)
    return H


def test_smooth_min_derivatives():
    z = np.linspace(-0.5, 2.5, 61)
    s, s1, s2 = smooth_min1(z, 0.05)
    h = 1e-5
    # central differences: truncation ~h^2 s''' ~ 1e-10 * (1/w^2 = 400) plus round-off 1e-16 / 1e-5
    np.testing.assert_allclose(s1, (smooth_min1(z + h, 0.05)[0] - smooth_min1(z - h, 0.05)[0]) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(s2, (smooth_min1(z + h, 0.05)[1] - smooth_min1(z - h, 0.05)[1]) / (2 * h), atol=1e-5)
    assert np.all(s <= np.minimum(z, 1.0)) and np.max(np.minimum(z, 1.0) - s) <= 0.025 + 1e-12  # w / 2


def test_gradient_matches_finite_differences_on_furnace_model(model, short_ref):
    K = 12
    t = np.arange(K + 1) * 1.0
    inputs = ScaledDistribution(model.m, K, 0.05)
    sh = _shooting(model, inputs, K, short_ref(t))
    rng = np.random.default_rng(3)
    d = rng.uniform(0.1, 0.3, model.m)
    p = np.concatenate([d / d.sum(), rng.uniform(1.0, 5.0, K)])
    g = sh.sweep(p).grad
    g_fd = _fd_grad(sh, p, 1e-6)
    # central differences with eps = 1e-6 on a cost ~1e4: round-off ~1e-16 * 1e4 / 1e-6 ~ 1e-6 absolute,
    # truncation ~eps^2 * f''' tiny: 1e-6 relative to the largest component is a safe bound
    assert np.max(np.abs(g - g_fd)) <= 1e-6 * np.max(np.abs(g_fd))


@pytest.mark.parametrize("kind", ["scaled", "free"])
def test_hessian_is_exact_on_a_linear_model(kind):
    """Without radiation the stand-in is linear: Gauss-Newton + input curvature is the exact Hessian."""
    model = make_standin()
    model.k_r = np.zeros(model.n)
    model.A_c = model.A_c - 0.05 * np.eye(model.n)
    K = 8
    T_knots = np.linspace(400.0, 900.0, K + 1)
    rng = np.random.default_rng(1)
    if kind == "scaled":
        inputs = ScaledDistribution(model.m, K, 0.2)
        d = rng.uniform(0.2, 0.5, model.m)
        p = np.concatenate([d / d.sum(), rng.uniform(1.0, 4.0, K)])  # v d crosses 1: saturation curvature
    else:
        inputs = FreeInputs(model.m, K)
        p = rng.uniform(0.1, 0.9, model.m * K)
    reg = np.full(inputs.n_params, 1e-3)
    sh = CoarseShooting(model, np.full(model.n, T0), 1.0, 2, T_knots, np.full(K, 1.0 / K), 100.0, 1.0,
                        inputs, reg)
    H = sh.sweep(p).hess
    H_fd = _fd_hess(sh, p, 1e-6)
    # exact up to the central-difference error of the gradient (~1e-6 relative, see above)
    assert np.max(np.abs(H - H_fd)) <= 1e-5 * np.max(np.abs(H_fd))


# ---------------------------------------------------------------- the OCP
def test_plan_satisfies_constraints_and_ipopt_succeeded(plan, model):
    assert plan.success and plan.status == "Solve_Succeeded", plan.status
    assert plan.iterations > 0
    # (20d), (20e): 0 <= u_c <= 1 with max(u_c) = 1 exactly (rescaled distribution)
    assert np.all(plan.u_c >= 0.0) and np.all(plan.u_c <= 1.0) and plan.u_c.max() == 1.0
    # (18): u_ff,j = sat(v_j u_c) at every sample, inputs in [0, 1]
    np.testing.assert_array_equal(plan.u_ff, np.clip(plan.v[:, None] * plan.u_c[None, :], 0.0, 1.0))
    assert plan.u_ff.shape == (240, model.m) and np.all(plan.v >= 0.0)
    # horizon beta t_E = 1.2 * 20 s = 24 s = 240 samples of 0.1 s
    assert plan.t[-1] == pytest.approx(24.0) and plan.t_s == pytest.approx(0.1)
    # theta_ref is the fine model (12a) driven by u_ff from theta0 (eq. 17 text)
    np.testing.assert_allclose(plan.theta_ref, simulate(model, plan.theta_ref[0], plan.u_ff), rtol=1e-12)
    np.testing.assert_allclose(plan.T_mean, plan.theta_ref @ model.c_m, rtol=1e-12)


def test_feedforward_alone_tracks_the_reference_on_the_nominal_model(plan, cfg):
    e = plan.T_mean - plan.T_ref
    j_E = plan.index_at(20.0)
    setpoint = 700.0
    # the paper's closed-loop figures (section 5.1): |mean error| < 2 % of the setpoint in the
    # transient and < 0.5 % in steady state; the feedforward on its own nominal model must do as well
    assert np.max(np.abs(e[: j_E + 1])) < 0.02 * setpoint
    assert np.max(np.abs(e[j_E:])) < 0.005 * setpoint


def test_free_ocp_is_not_worse_than_the_parametrized_one(plan, model, cfg, short_ref):
    # Remark 4: (18) restricts the inputs; every parametrized plan is a feasible free plan on the
    # same intervals, so the free optimum started from it can only be lower (1e-3 relative slack
    # for the smoothing of sat in the parametrized OCP, at most w/2 = 0.005 in u)
    free = solve_feedforward(model, plan.theta_ref[0], 0.0, short_ref, cfg, warm_start=plan, parametrized=False,
                             horizon=HORIZON)
    assert free.success, free.status
    assert free.u_c is None and np.all(free.u_ff >= 0.0) and np.all(free.u_ff <= 1.0)
    assert free.objective <= plan.objective * (1.0 + 1e-3)


def test_ipopt_failure_raises_unless_best_effort(model, cfg, short_ref):
    theta0 = np.full(model.n, T0)
    with pytest.raises(FeedforwardError) as info:
        solve_feedforward(model, theta0, 0.0, short_ref, cfg, max_iter=1, horizon=HORIZON)
    assert info.value.status == "Maximum_Iterations_Exceeded"
    best = solve_feedforward(model, theta0, 0.0, short_ref, cfg, max_iter=1, best_effort=True, horizon=HORIZON)
    assert not best.success and best.status == "Maximum_Iterations_Exceeded" and best.iterations == 1


def test_plan_from_a_later_start_time(model, cfg):
    ref = reference_trajectory(TransitionReference(setpoint=600.0, t_E=10.0), T0, t_start=50.0)
    plan = solve_feedforward(model, np.full(model.n, T0), 50.0, ref, cfg, horizon=12.0)
    assert plan.t[0] == 50.0 and plan.index_at(55.0) == 50 and plan.t[-1] == pytest.approx(62.0)
    assert plan.success


def test_transition_end_of_plain_callables():
    ref = reference_trajectory(TransitionReference(setpoint=900.0, t_E=30.0), T0)

    def shifted(t):
        return ref(np.asarray(t) - 12.0)  # how the loop shifts a reference in time

    assert transition_end(ref, 0.0, 0.1) == 30.0
    # found by scanning on the 0.1 s grid: exact to one sample
    assert abs(transition_end(shifted, 0.0, 0.1) - 42.0) <= 0.1 + 1e-9
    assert transition_end(lambda t: np.full_like(np.asarray(t, float), 800.0), 5.0, 0.1) == 5.0


def test_default_horizon_is_beta_t_E_or_the_settling_time(model, cfg):
    from twin.control.ocp_grid import SETTLE_TIME_CONSTANTS, mean_time_constant

    ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=120.0), T0)
    tau = mean_time_constant(model, np.full(model.n, 1100.0), np.full(model.m, 0.5))
    assert cfg.feedforward.beta * 120.0 > SETTLE_TIME_CONSTANTS * tau  # the paper's rule applies here
    # a constant reference (re-plan in steady state): only the settling horizon is left
    flat = solve_feedforward(model, np.full(model.n, 1100.0), 0.0, lambda t: np.full_like(np.asarray(t, float),
                             1100.0), cfg, max_iter=1, best_effort=True)
    expected = int(np.ceil(SETTLE_TIME_CONSTANTS * tau - 1e-9))  # whole 1 s intervals
    assert flat.t[-1] == pytest.approx(float(expected))
    assert ref.t_end == 120.0


def test_heating_efficiency_is_normalized_and_positive(model):
    eta = heating_efficiency(model, np.full(model.n, 900.0))
    assert np.all(eta > 0) and eta.mean() == pytest.approx(1.0, rel=1e-12)
