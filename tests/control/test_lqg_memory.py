"""What the LQG design keeps for the MPC (twin.control.lqg.Gains.linearisation, .cost_to_go), checked by index.

The MPC (twin.control.mpc) takes its prediction model and terminal cost from the gains: Phi_j, Gamma_j of eq. (23)
as the design held them (every ``jacobian_every`` samples) and P_j of the recursion (29).  Oracles: the stand-in
plant's own Jacobians at the plan's points (its T^4 radiation makes them differ from sample to sample), the
terminal P_S from ``scipy.linalg.solve_discrete_are`` and the recursion (29) written out here with the augmented
matrices of eq. (24) and the weight of eq. (28) built by hand.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from controller_standin import make_standin

from twin.config import small_config
from twin.control.lqg import Gains, anti_windup_delta, lqg_gains
from twin.control.plan import FeedforwardPlan

EVERY = 4
N = 22  # not a multiple of EVERY: the last held block is short


@pytest.fixture(scope="module")
def design():
    cfg = small_config().with_overrides({"lqg.delta0": 2.0})  # the plan's total power crosses it (3 groups here)
    model = make_standin()
    t = np.arange(N + 1) * model.t_s
    ramp = np.linspace(800.0, 1100.0, N + 1)
    theta_ref = ramp[:, None] + np.linspace(-20.0, 20.0, model.n)[None, :]
    level = 0.2 + 0.7 * np.sin(np.pi * np.arange(N) / (N - 1))  # up and down: delta switches both ways
    u_ff = np.clip(level[:, None] * np.array([1.0, 1.2, 0.8])[None, :], 0.0, 1.0)
    plan = FeedforwardPlan(t=t, u_ff=u_ff, theta_ref=theta_ref, T_ref=ramp, T_mean=ramp, status="test", iterations=0,
                           solve_s=0.0, success=True)
    return cfg, model, plan, lqg_gains(model, plan, cfg, jacobian_every=EVERY)


def _augmented(model, Phi, Gamma, delta):
    n, m = Gamma.shape
    Pt = np.block([[Phi, np.zeros((n, 1))], [delta * model.t_s * model.c_m[None, :], np.ones((1, 1))]])
    Gt = np.vstack([Gamma, np.zeros((1, m))])
    return Pt, Gt


def test_the_linearisation_is_the_models_jacobian_at_the_held_point(design) -> None:
    cfg, model, plan, gains = design
    for j in range(N):
        jj = (j // EVERY) * EVERY
        Phi, Gamma = gains.linearisation(j)
        np.testing.assert_array_equal(Phi, model.jac_theta(plan.theta_ref[jj], plan.u_ff[jj]))
        np.testing.assert_array_equal(Gamma, model.jac_u(plan.theta_ref[jj], plan.u_ff[jj]))
    assert not np.array_equal(gains.linearisation(0)[0], gains.linearisation(EVERY)[0])  # the premise: they differ
    for j in (N, N + 7, -1):  # beyond the plan (and before it): the terminal point's, at the last input
        Phi, Gamma = gains.linearisation(j)
        np.testing.assert_array_equal(Phi, model.jac_theta(plan.theta_ref[N], plan.u_ff[-1]))
        np.testing.assert_array_equal(Gamma, model.jac_u(plan.theta_ref[N], plan.u_ff[-1]))


def test_the_cost_to_go_is_the_recursion_from_the_terminal_dare(design) -> None:
    cfg, model, plan, gains = design
    w = cfg.lqg
    n = model.n
    Q = np.zeros((n + 1, n + 1))
    Q[:n, :n] = w.q0 * np.outer(model.c_m, model.c_m)
    Q[n, n] = w.q1
    PtN, GtN = _augmented(model, model.jac_theta(plan.theta_ref[N], plan.u_ff[-1]),
                          model.jac_u(plan.theta_ref[N], plan.u_ff[-1]), 1.0)
    P = scipy.linalg.solve_discrete_are(PtN, GtN, Q, w.r0 * np.eye(model.m))
    np.testing.assert_allclose(gains.cost_to_go(N), P, rtol=1e-7, atol=1e-9)
    np.testing.assert_array_equal(gains.cost_to_go(N + 3), gains.P_terminal)
    expected = {}
    for j in range(N - 1, -1, -1):
        jj = (j // EVERY) * EVERY
        Pt, Gt = _augmented(model, model.jac_theta(plan.theta_ref[jj], plan.u_ff[jj]),
                            model.jac_u(plan.theta_ref[jj], plan.u_ff[jj]),
                            anti_windup_delta(plan.u_ff[j], w.delta0))
        S = w.r0 * np.eye(model.m) + Gt.T @ P @ Gt
        P = Q + Pt.T @ P @ Pt - Pt.T @ P @ Gt @ np.linalg.solve(S, Gt.T @ P @ Pt)
        P = 0.5 * (P + P.T)
        if j % EVERY == 0:
            expected[j] = P
    assert {anti_windup_delta(u, w.delta0) for u in plan.u_ff} == {0.0, 1.0}  # the premise: both deltas occur
    for j, Pj in expected.items():
        np.testing.assert_allclose(gains.cost_to_go(j), Pj, rtol=1e-7, atol=1e-9 * np.abs(Pj).max())


def test_the_cost_to_go_is_kept_at_multiples_only_and_asked_of_a_full_design(design) -> None:
    cfg, model, plan, gains = design
    with pytest.raises(ValueError, match=f"multiples of {EVERY} samples only, not at 5"):
        gains.cost_to_go(5)
    bare = Gains(gains.K, gains.K_terminal, gains.P_terminal, EVERY)
    with pytest.raises(ValueError, match="without their cost-to-go"):
        bare.cost_to_go(0)
    with pytest.raises(ValueError, match="without their linearisation"):
        bare.linearisation(0)
    no_terminal = Gains(gains.K, gains.K_terminal, gains.P_terminal, EVERY, 0.0, gains.Phi, gains.Gamma, gains.P)
    with pytest.raises(ValueError, match="without their linearisation"):
        no_terminal.linearisation(0)


def test_the_design_asks_its_budget_every_check_every_samples_and_stops_when_told(design) -> None:
    """``check`` is called at j = 100, 50, 0 of a 120-sample design (every CHECK_EVERY = 50, counted backwards) and
    whatever it raises ends the design (a cancelled or spent plan budget)."""
    from twin.control.lqg import CHECK_EVERY

    cfg, model, plan, _ = design
    n = 120
    long = FeedforwardPlan(t=np.arange(n + 1) * model.t_s, u_ff=np.tile(plan.u_ff[0], (n, 1)),
                           theta_ref=np.tile(plan.theta_ref[0], (n + 1, 1)), T_ref=np.full(n + 1, 800.0),
                           T_mean=np.full(n + 1, 800.0), status="test", iterations=0, solve_s=0.0, success=True)
    calls: list[int] = []
    lqg_gains(model, long, cfg, check=lambda: calls.append(1))
    assert CHECK_EVERY == 50 and len(calls) == 3

    class Spent(Exception):
        pass

    def spent() -> None:
        raise Spent

    with pytest.raises(Spent):
        lqg_gains(model, long, cfg, check=spent)
