"""The integrator's transfer to a calibration's re-plan (twin.control.lqg.carried_integrator).

Oracle: the defining equations on hand-made plans and gains (3 states, 3 groups), where the answer is known in
closed form or found by search, and the controllers' own input (eq. 25, ``feedback_control``) before and after
the switch: the integrator's part k e_I of the input gives up what the new plan's input carries at the switch,
in least squares over the groups the old input did not clip.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from twin.control.lqg import Gains, IntegratorState, carried_integrator, feedback_control
from twin.control.plan import FeedforwardPlan

N, n, m = 20, 3, 3
T_S = 0.1


def _plan(u_ff: np.ndarray, theta_ref: float, t0: float = 0.0) -> FeedforwardPlan:
    t = t0 + T_S * np.arange(N + 1)
    return FeedforwardPlan(t=t, u_ff=np.tile(u_ff, (N, 1)), theta_ref=np.full((N + 1, n), theta_ref),
                           T_ref=np.full(N + 1, theta_ref), T_mean=np.full(N + 1, theta_ref), status="ok",
                           iterations=0, solve_s=0.0, success=True)


def _gains(k_x: float, k_i: np.ndarray) -> Gains:
    K = np.zeros((m, n + 1))
    K[:, :n] = k_x / n
    K[:, n] = k_i
    return Gains(K=np.tile(K, (N, 1, 1)), K_terminal=K, P_terminal=np.eye(n + 1))


def test_what_the_new_feedforward_carries_comes_off_the_integrator() -> None:
    """Weaker lamps learnt: the new plan's feedforward is 0.1 higher in every group; with k = -0.01 per K s the
    integrator had been making up 0.2 (e_I = -20 K s), so 0.1 is left: e_I = -10 K s."""
    k = np.full(m, -0.01)
    old = _plan(np.array([0.4, 0.5, 0.6]), 1000.0)
    new = _plan(np.array([0.5, 0.6, 0.7]), 1000.0)
    state = carried_integrator(old, _gains(-0.02, k), new, _gains(-0.02, k), 1.0, np.full(n, 1000.0),
                               IntegratorState(-20.0))
    assert state.e_I == pytest.approx(-10.0)


def test_the_input_does_not_jump_at_the_switch() -> None:
    """The new plan starts 0.2 lower than the old one in every group, and later rises (the first samples count,
    not the plan's later level); the estimate is 3 K off both plans' reference states.  The old and the new
    controller (feedback_control, eq. 25, on their own plans and gains) apply the same input at the switch."""
    k = np.full(m, -0.01)
    old = _plan(np.array([0.4, 0.5, 0.6]), 1000.0)
    u_new = np.tile(np.array([0.2, 0.3, 0.4]), (N, 1))
    u_new[4:] += 0.5  # later: another level, which does not count
    new = dataclasses.replace(old, u_ff=u_new, theta_ref=np.full((N + 1, n), 998.0))
    theta = np.full(n, 1003.0)
    g_old, g_new = _gains(-0.02, k), _gains(-0.03, 1.5 * k)
    state = carried_integrator(old, g_old, new, g_new, 0.0, theta, IntegratorState(-20.0))
    c_m = np.full(n, 1.0 / n)
    u_old, _ = feedback_control(g_old, old, c_m, 1.0, 0, theta, IntegratorState(-20.0))
    u_switch, _ = feedback_control(g_new, new, c_m, 1.0, 0, theta, state)
    np.testing.assert_allclose(u_switch.u, u_old.u, atol=1e-12)
    assert 0.0 < u_old.u.min() and u_old.u.max() < 1.0  # no group clipped: all of them matched


def test_least_squares_over_the_groups_with_other_gains() -> None:
    """k_new differs from k_old and no e_I' meets every group: the least-squares e_I', against a search."""
    rng = np.random.default_rng(3)
    theta = np.array([995.0, 1001.0, 1003.0])
    old, new = _plan(np.array([0.3, 0.5, 0.7]), 1000.0), _plan(np.array([0.35, 0.52, 0.8]), 999.0, t0=0.5)
    g_old, g_new = _gains(-0.03, np.array([-0.01, -0.012, -0.008])), _gains(-0.02, rng.uniform(-0.02, -0.005, m))
    state = carried_integrator(old, g_old, new, g_new, 1.0, theta, IntegratorState(-15.0))
    K_old, K_new = g_old.K_terminal, g_new.K_terminal
    u_old = old.u_ff[0] + K_old @ np.append(theta - old.theta_ref[0], -15.0)
    grid = np.linspace(-40.0, 20.0, 60001)
    miss = [np.sum((new.u_ff[0] + K_new @ np.append(theta - new.theta_ref[0], e) - u_old) ** 2) for e in grid]
    best = grid[np.argmin(miss)]
    assert state.e_I == pytest.approx(best, abs=2e-3)


def test_clipped_groups_give_nothing_to_match() -> None:
    """A group the old input clipped at full power (banded's vertical lamps in the hold) is left out of the
    match: the others' inputs are kept exactly.  With every group clipped, e_I is kept."""
    k = np.array([-0.01, -0.02, -0.01])
    old = _plan(np.array([0.95, 0.5, 0.6]), 1000.0)  # group 1 at 0.95 + 0.2 > 1: clipped
    new = _plan(np.array([0.99, 0.7, 0.7]), 1000.0)
    state = carried_integrator(old, _gains(0.0, k), new, _gains(0.0, k), 1.0, np.full(n, 1000.0),
                               IntegratorState(-20.0, frozen=True))
    # groups 2, 3: 0.5 + 0.4 = 0.7 - 0.02 e' and 0.6 + 0.2 = 0.7 - 0.01 e' are both met by e' = -10 (group 1
    # would ask for -16)
    assert state.e_I == pytest.approx(-10.0) and state.frozen
    saturated = _plan(np.array([1.2, 1.3, 1.1]), 1000.0)
    kept = carried_integrator(saturated, _gains(0.0, k), new, _gains(0.0, k), 1.0, np.full(n, 1000.0),
                              IntegratorState(-20.0))
    assert kept.e_I == -20.0


def test_an_old_plan_past_its_horizon_holds_its_last_input() -> None:
    """A calibration comes in the hold, after the first plan's horizon (beta t_E = 144 s in the paper's run):
    that plan holds its last input (FeedforwardPlan.sample), and the transfer compares the new plan with it (a
    first version compared nothing there and kept e_I, measured as no change on six runs)."""
    k = np.full(m, -0.01)
    old = _plan(np.array([0.4, 0.5, 0.6]), 1000.0)  # 2 s long
    new = _plan(np.array([0.5, 0.6, 0.7]), 1000.0, t0=5.0)
    state = carried_integrator(old, _gains(-0.02, k), new, _gains(-0.02, k), 5.0, np.full(n, 1000.0),
                               IntegratorState(-20.0))
    assert state.e_I == pytest.approx(-10.0)
