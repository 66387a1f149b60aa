"""The integrator's transfer to a calibration's re-plan (twin.control.lqg.carried_integrator).

Oracle: the defining equations on hand-made plans and gains (3 states, 3 groups), where the answer is known in
closed form or found by search: the integrator's part k e_I of the input (eq. 25) gives up the rise of the
feedforward's level, in least squares over the groups the old input did not clip.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from twin.control.lqg import Gains, IntegratorState, carried_integrator
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


def test_the_new_plans_level_counts_not_its_first_samples_nor_its_end() -> None:
    """The new plan starts 1 s lower (it brings an estimate above the reference down itself) and ends with a
    glitch; its level in between is 0.1 above the old plan's: the integrator gives up 0.1, as with constant plans."""
    k = np.full(m, -0.01)
    old = _plan(np.array([0.4, 0.5, 0.6]), 1000.0)
    u_new = np.tile(np.array([0.5, 0.6, 0.7]), (N, 1))
    u_new[:4] -= 0.3  # the first samples: the plan's own correction
    u_new[-2:] += 0.5  # the end
    new = dataclasses.replace(old, u_ff=u_new)
    state = carried_integrator(old, _gains(-0.02, k), new, _gains(-0.02, k), 0.0, np.full(n, 1000.0),
                               IntegratorState(-20.0))
    assert state.e_I == pytest.approx(-10.0)


def test_least_squares_over_the_groups_with_other_gains() -> None:
    """k_new differs from k_old and no e_I' meets every group: the least-squares e_I', against a search."""
    rng = np.random.default_rng(3)
    theta = np.array([995.0, 1001.0, 1003.0])
    old, new = _plan(np.array([0.3, 0.5, 0.7]), 1000.0), _plan(np.array([0.35, 0.52, 0.8]), 999.0, t0=0.5)
    g_old, g_new = _gains(-0.03, np.array([-0.01, -0.012, -0.008])), _gains(-0.02, rng.uniform(-0.02, -0.005, m))
    state = carried_integrator(old, g_old, new, g_new, 1.0, theta, IntegratorState(-15.0))
    k_old, k_new = g_old.K_terminal[:, n], g_new.K_terminal[:, n]
    delta = new.u_ff[0] - old.u_ff[0]
    grid = np.linspace(-40.0, 20.0, 60001)
    best = grid[np.argmin([np.sum((k_new * e - (k_old * -15.0 - delta)) ** 2) for e in grid])]
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
