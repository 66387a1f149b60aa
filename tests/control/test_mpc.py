"""The MPC feedback (twin.control.mpc) on a small linear time-varying system: the LQG when no bound is active,
scipy's solution of the same constrained problem written out step by step, bounds and rates never violated,
and a saturated group's share taken over by the others."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize
from controller_standin import make_standin

from twin.config import small_config
from twin.control.lqg import IntegratorState, anti_windup_delta, augmented_system, lqg_gains, weight_matrix
from twin.control.mpc import MPCController, MPCSettings, condensed_qp, horizon_end, move_blocks
from twin.control.plan import FeedforwardPlan, simulate
from twin.control.qp import make_solver
from twin.control.reference import steady_state

EVERY = 5  # the design's Jacobian hold in these tests (the loop uses 10)


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def standin():
    return make_standin(nx=4, ny=3, m=3)


def _plan(model, u_ff):
    """A plan along the inputs u_ff (N, m) from the steady state of u_ff[0]: time-varying linearisation."""
    theta0 = steady_state(model, u_ff[0], np.full(model.n, 900.0))
    theta = simulate(model, theta0, u_ff)
    T = theta @ model.c_m
    t = np.arange(len(u_ff) + 1) * model.t_s
    return FeedforwardPlan(t=t, u_ff=u_ff, theta_ref=theta, T_ref=T, T_mean=T, status="test", iterations=0,
                           solve_s=0.0, success=True)


@pytest.fixture(scope="module")
def ramp(standin, cfg):
    """u_ff from 0.3 to 0.6 over 200 samples: interior, so no bound is active for small deviations."""
    u_ff = np.linspace(0.3, 0.6, 200)[:, None] * np.ones(standin.m)
    plan = _plan(standin, u_ff)
    return plan, lqg_gains(standin, plan, cfg, jacobian_every=EVERY)


@pytest.fixture(scope="module")
def high(standin, cfg):
    """Group 0 at full power in the plan, the others at 0.5."""
    u = np.array([1.0, 0.5, 0.5])
    plan = _plan(standin, np.tile(u, (200, 1)))
    return plan, lqg_gains(standin, plan, cfg, jacobian_every=EVERY)


def _e0(model, scale, e_I=0.0, seed=0):
    rng = np.random.default_rng(seed)
    return np.append(scale * (1.0 + 0.3 * rng.normal(size=model.n)), e_I)


def test_move_blocks_and_horizon_end():
    assert move_blocks(30, 5) == [1, 8, 7, 7, 7] and sum(move_blocks(23, 4)) == 23
    assert move_blocks(4, 10) == [1, 1, 1, 1] and move_blocks(7, 1) == [7]
    # ends at a multiple of the hold (where the design kept P_j), never at j itself; j + H past the plan
    assert horizon_end(12, 30, 10, 500) == 40 and horizon_end(19, 3, 10, 500) == 20
    assert horizon_end(480, 30, 10, 500) == 510


def test_without_active_bounds_the_first_move_is_the_lqg(standin, cfg, ramp):
    """One move per sample, no bound active: the QP's minimiser is the LQ solution, whose first move is
    K_j e_j of the Riccati recursion (29) (the terminal cost is the recursion's own P at the horizon's end)."""
    plan, gains = ramp
    w = cfg.lqg
    settings = MPCSettings(horizon=30, moves=30, rate=10.0)
    solver = make_solver("osqp")
    for j, scale in ((37, 0.5), (3, -0.8), (190, 0.3)):  # 190: the horizon runs past the plan (P_S)
        e0 = _e0(standin, scale, e_I=0.2, seed=j)
        pred = condensed_qp(gains, plan, standin.c_m, w.q0, w.q1, w.r0, w.delta0, j, e0, None, settings)
        lqg = gains.at(j) @ e0
        assert np.all(np.abs(lqg) < 0.25), "the test needs a deviation small enough to stay inside the bounds"
        res = solver.solve(pred.qp)
        assert res.ok, res.status
        np.testing.assert_allclose(res.z[: standin.m], lqg, rtol=1e-4, atol=1e-6 * np.abs(lqg).max())


def test_controller_uses_the_deviation_from_the_plan(standin, cfg, ramp):
    """MPCController.control: e = [theta_hat - theta_ref,j ; e_I] (eq. 24); u = u_ff + the first move."""
    plan, gains = ramp
    ctl = MPCController(standin, plan, gains, cfg, IntegratorState(0.3),
                        settings=MPCSettings(horizon=30, moves=30, rate=10.0))
    j = 60
    dev = 0.4 * np.cos(np.arange(standin.n))
    u, u_ff, du = ctl.control(j, plan.theta_ref[j] + dev)
    expected = gains.at(j) @ np.append(dev, 0.3)
    np.testing.assert_allclose(du, expected, rtol=1e-4, atol=1e-8)
    np.testing.assert_allclose(u, plan.u_ff[j] + expected, rtol=1e-4)
    # the integral state integrates the mean error against T_ref (eq. 22)
    mean_err = float(standin.c_m @ (plan.theta_ref[j] + dev)) - plan.T_ref[j]
    assert ctl.state.e_I == pytest.approx(0.3 + plan.t_s * mean_err)


def _explicit_cost(z, gains, plan, model, cfg, j, e0, blocks):
    """The MPC's cost written out: the augmented system (24) stepped sample by sample with held moves."""
    w = cfg.lqg
    Q = weight_matrix(model.c_m, w.q0, w.q1)
    m = model.m
    x = e0.copy()
    cost = 0.0
    k = 0
    for b, length in enumerate(blocks):
        du = z[b * m:(b + 1) * m]
        for _ in range(length):
            Phi, Gam = gains.linearisation(j + k)
            delta = anti_windup_delta(plan.sample(j + k)[0], w.delta0)
            Pt, Gt = augmented_system(Phi, Gam, model.c_m, model.t_s, delta)
            cost += x @ Q @ x + w.r0 * du @ du
            x = Pt @ x + Gt @ du
            k += 1
    return cost + x @ gains.cost_to_go(j + k) @ x


def test_constrained_qp_matches_scipy(standin, cfg, high):
    """Group 0 planned at full power, the plate 15 K too cold: the bounds are active.  The condensed QP
    solved by OSQP against scipy's SLSQP on the explicit problem (bounds 0 <= u_ff + du <= 1 per move,
    rate bounds between the moves)."""
    plan, gains = high
    j, m = 20, standin.m
    settings = MPCSettings(horizon=20, moves=4, rate=0.05)
    e0 = _e0(standin, -15.0, e_I=-5.0)
    w = cfg.lqg
    u_prev = plan.u_ff[j]
    pred = condensed_qp(gains, plan, standin.c_m, w.q0, w.q1, w.r0, w.delta0, j, e0, u_prev, settings)
    res = make_solver("osqp").solve(pred.qp)
    assert res.ok
    blocks = pred.blocks
    H = sum(blocks)
    nz = m * len(blocks)
    u_ff = np.array([plan.sample(j + k)[0] for k in range(H)])
    starts = np.cumsum([0, *blocks[:-1]])
    bounds = []
    for b, (k0, length) in enumerate(zip(starts, blocks, strict=True)):
        for i in range(m):
            seg = u_ff[k0:k0 + length, i]
            lo, hi = float(np.max(-seg)), float(np.min(1.0 - seg))
            if b == 0:
                lo, hi = max(lo, u_prev[i] - 0.05 - u_ff[0, i]), min(hi, u_prev[i] + 0.05 - u_ff[0, i])
            bounds.append((lo, hi))

    def rate(z):  # >= 0: |u at the start of move b - u at the end of move b - 1| <= rate
        out = []
        for b in range(1, len(blocks)):
            jump = (u_ff[starts[b]] + z[b * m:(b + 1) * m]) - (u_ff[starts[b] - 1] + z[(b - 1) * m:b * m])
            out.extend(0.05 - jump)
            out.extend(0.05 + jump)
        return np.array(out)

    scale = 1e-3  # SLSQP on a cost of ~1e5 K^2
    ref = scipy.optimize.minimize(lambda z: scale * _explicit_cost(z, gains, plan, standin, cfg, j, e0, blocks),
                                  np.zeros(nz), method="SLSQP", bounds=bounds,
                                  constraints=[{"type": "ineq", "fun": rate}],
                                  options={"ftol": 1e-12, "maxiter": 500})
    assert ref.success, ref.message
    assert res.z[0] == pytest.approx(0.0, abs=1e-6)  # group 0 is at its upper bound
    assert np.any(np.abs(res.z[1:m]) > 0.01)  # the others move
    np.testing.assert_allclose(res.z, ref.x, atol=2e-4)
    assert _explicit_cost(res.z, gains, plan, standin, cfg, j, e0, blocks) <= \
        _explicit_cost(ref.x, gains, plan, standin, cfg, j, e0, blocks) * (1 + 1e-6)


def test_the_fillet_variance_weight_matches_the_explicit_problem(standin, cfg, high, ramp):
    """``homogeneity`` = q_W: the QP minimises the explicit cost plus q_W theta_H^T W theta_H (eq. 21, theta_H =
    theta_ref,H + d_H at the horizon's end), checked against the explicit problem by scipy (no bounds active;
    the reference holds still in this plan).  In a ramp, where the reference moves, the term is left out."""
    plan, gains = high
    j, q_w = 20, 50.0
    settings = MPCSettings(horizon=20, moves=4, rate=10.0, homogeneity=q_w)
    e0 = _e0(standin, 0.5, e_I=0.1)
    w = cfg.lqg
    pred = condensed_qp(gains, plan, standin.c_m, w.q0, w.q1, w.r0, w.delta0, j, e0, None, settings,
                        W=standin.W)
    blocks, H = pred.blocks, sum(pred.blocks)

    def cost(z):
        k, x = 0, e0[:standin.n].copy()
        for b, length in enumerate(blocks):  # the nodes' deviation d_H under the held moves
            for _ in range(length):
                Phi, Gam = gains.linearisation(j + k)
                x = Phi @ x + Gam @ z[b * standin.m:(b + 1) * standin.m]
                k += 1
        theta_H = plan.theta_ref[j + H] + x
        return _explicit_cost(z, gains, plan, standin, cfg, j, e0, blocks) + q_w * theta_H @ standin.W @ theta_H

    ref = scipy.optimize.minimize(cost, np.zeros(pred.qp.g.size), method="BFGS", options={"gtol": 1e-9})
    z = np.linalg.solve(pred.qp.H, -pred.qp.g)  # the QP's unconstrained minimiser
    np.testing.assert_allclose(z, ref.x, atol=1e-5 * max(1.0, np.abs(ref.x).max()))
    plain = condensed_qp(gains, plan, standin.c_m, w.q0, w.q1, w.r0, w.delta0, j, e0, None,
                         MPCSettings(horizon=20, moves=4, rate=10.0))
    assert np.abs(np.linalg.solve(plain.qp.H, -plain.qp.g) - z).max() > 1e-4  # the weight matters here
    ramp_plan, ramp_gains = ramp
    a, b = (condensed_qp(ramp_gains, ramp_plan, standin.c_m, w.q0, w.q1, w.r0, w.delta0, j, e0, None, st, W=standin.W)
            for st in (settings, MPCSettings(horizon=20, moves=4, rate=10.0)))
    np.testing.assert_array_equal(a.qp.H, b.qp.H)


def test_a_saturated_group_is_taken_over_by_the_others(standin, cfg, high):
    """Too cold with group 0 at full power: the LQG clips group 0's correction and loses it; the MPC puts
    more on the groups that still have room, and the predicted mean error shrinks faster."""
    plan, gains = high
    j = 40
    theta_hat = plan.theta_ref[j] - 20.0
    lqg_u = np.clip(plan.u_ff[j] + gains.at(j) @ np.append(theta_hat - plan.theta_ref[j], 0.0), 0.0, 1.0)
    ctl = MPCController(standin, plan, gains, cfg, settings=MPCSettings(horizon=30, moves=5, rate=1.0))
    u, _, _ = ctl.control(j, theta_hat)
    assert lqg_u[0] == 1.0 and u[0] == pytest.approx(1.0, abs=1e-6)
    assert np.all(u[1:] > lqg_u[1:] + 1e-3)  # (the paper's r0 = 1e4 makes every move cautious)

    def mean_after(u_applied, steps=10):
        th = theta_hat.copy()
        for _ in range(steps):
            th = standin.step(th, u_applied)
        return float(standin.c_m @ th)

    assert mean_after(u) > mean_after(lqg_u) + 0.1  # K warmer after 1 s (0.20 K when written)


def test_bounds_and_rates_hold_in_closed_loop(cfg, high):
    """The plant's lamps 25 % weaker than the model's: the feedback runs into its bounds.  Every move the QP
    returns keeps 0 <= u_ff + du <= 1 (before any clipping) and |u_j - u_j-1| <= rate t_s."""
    plan, gains = high
    plant = make_standin(nx=4, ny=3, m=3, gain_scale=0.75)
    model = make_standin(nx=4, ny=3, m=3)
    settings = MPCSettings(horizon=20, moves=4, rate=0.02)
    ctl = MPCController(model, plan, gains, cfg, settings=settings)
    theta = plan.theta_ref[0] - 30.0
    u_prev = None
    for j in range(120):
        u, u_ff, du = ctl.control(j, theta)
        raw = u_ff + du
        assert np.all(raw >= -1e-7) and np.all(raw <= 1.0 + 1e-7), (j, raw)
        if u_prev is not None:
            assert np.all(np.abs(u - u_prev) <= settings.rate + 1e-7), (j, u - u_prev)
        u_prev = u
        theta = plant.step(theta, u)
    assert ctl.fallbacks == 0
    assert np.any(np.isclose(u_prev, 0.0, atol=1e-6) | np.isclose(u_prev, 1.0, atol=1e-6))  # a bound was met


def test_mpc_runs_the_furnace_loop(small_radiation):
    """The loop with ``control.feedback = "mpc"``: the MPC drives the small furnace."""
    from twin.runs.loop import ClosedLoop
    from twin.scenario import Scenario

    cfg = small_config()
    loop = ClosedLoop(cfg, Scenario(duration=1.0, reference={"setpoint": 500.0, "t_E": 10.0},
                                    control={"feedback": "mpc"}), small_radiation)
    snaps = list(loop.run())
    assert isinstance(loop.controller, MPCController) and loop.controller.fallbacks == 0
    u = np.array([s.u for s in snaps])
    assert np.all((u >= 0.0) & (u <= 1.0)) and len(loop.controller.step_ms) == len(snaps)


def test_the_plans_deltas_made_once_give_the_same_qp(standin, cfg):
    """condensed_qp with the plan's deltas of Remark 5 made once (the controller's way, issue 21) builds the QP
    it builds from the horizon's own feedforward, to the bit: on a plan whose total power crosses delta0 inside
    the horizon, at its end (the last input held) and past it; and the deltas are those of anti_windup_delta."""
    from twin.control.mpc import anti_windup_deltas

    w = cfg.lqg
    total = np.linspace(0.5, 1.5, 120) * w.delta0  # 1^T u_ff crosses delta0 at sample 60
    plan = _plan(standin, (total / standin.m)[:, None] * np.ones(standin.m))
    gains = lqg_gains(standin, plan, cfg, jacobian_every=EVERY)
    deltas = anti_windup_deltas(plan.u_ff, w.delta0)
    assert deltas.tolist() == [anti_windup_delta(u, w.delta0) for u in plan.u_ff] and 0 < deltas.sum() < len(deltas)
    settings = MPCSettings(horizon=12, moves=4, rate=0.05)
    u_prev = plan.u_ff[0] + 0.01
    for j in (0, 52, 58, 111, 119, 125):
        e0 = _e0(standin, 0.4, e_I=0.3, seed=j)
        for with_rates in (True, False):
            a = condensed_qp(gains, plan, standin.c_m, w.q0, w.q1, w.r0, w.delta0, j, e0, u_prev, settings, with_rates)
            b = condensed_qp(gains, plan, standin.c_m, w.q0, w.q1, w.r0, w.delta0, j, e0, u_prev, settings, with_rates,
                             plan_deltas=deltas)
            for name in ("H", "g", "A", "lba", "uba", "lbx", "ubx"):
                assert getattr(a.qp, name).tobytes() == getattr(b.qp, name).tobytes(), (j, name)


def test_the_qps_shape_kept_between_samples_follows_the_input_weight_and_the_rates(standin, cfg, ramp):
    """What the QP's shape alone fixes is made once per shape (issue 21): the rate rows (none without rates,
    +-I between consecutive moves with them) and the input weight r0 |Delta u|^2 summed over each move's samples
    (the Hessian's difference between two r0), whatever was asked before; and a QP changed by its user does not
    change the next one."""
    plan, gains = ramp
    w = cfg.lqg
    settings = MPCSettings(horizon=12, moves=4, rate=0.05)
    e0 = _e0(standin, 0.4, e_I=0.3, seed=3)
    m = standin.m

    def qp(r0, with_rates):
        return condensed_qp(gains, plan, standin.c_m, w.q0, w.q1, r0, w.delta0, 40, e0, None, settings, with_rates)

    first = qp(w.r0, True)
    blocks = first.blocks
    nz = m * len(blocks)
    assert qp(w.r0, False).qp.A.shape == (0, nz)
    rates = qp(w.r0, True).qp.A
    assert rates.shape == ((len(blocks) - 1) * m, nz)
    np.testing.assert_array_equal(rates[:m, :2 * m], np.hstack([-np.eye(m), np.eye(m)]))
    heavier = qp(3.0 * w.r0, True).qp.H
    expected = np.diag(np.repeat(2.0 * w.r0 * np.asarray(blocks, float), m))
    np.testing.assert_allclose(heavier - first.qp.H, expected, rtol=1e-9, atol=1e-9 * np.abs(heavier).max())
    first.qp.H[:] = 0.0
    first.qp.A[:] = 0.0
    again = qp(w.r0, True).qp
    np.testing.assert_array_equal(again.A, rates)
    assert np.abs(again.H).max() > 0.0


@pytest.mark.parametrize("horizon, moves", [(12, 4), (17, 6), (9, 9)])
def test_the_condensed_cost_is_the_explicit_cost_at_every_phase_of_the_hold(standin, cfg, ramp, horizon, moves):
    """The condensing (several moves inside one held stretch, a move across two, a horizon past the plan) against
    the cost written out sample by sample (_explicit_cost): (J(z) - J(0)) / 2 = z^T H z / 2 + g^T z (the QP is half
    the cost: the same minimiser) for random moves, at every phase j mod EVERY of the design's hold (issue 21
    rewrote the per-step sums: a wrong step offset in a move's sum moves H by far more than the 1e-9 allowed here)."""
    plan, gains = ramp
    w = cfg.lqg
    settings = MPCSettings(horizon=horizon, moves=moves, rate=10.0)
    rng = np.random.default_rng(horizon + moves)
    for j in [*range(40, 40 + EVERY), 196]:
        e0 = _e0(standin, 0.7, e_I=0.2, seed=j)
        pred = condensed_qp(gains, plan, standin.c_m, w.q0, w.q1, w.r0, w.delta0, j, e0, None, settings)
        base = _explicit_cost(np.zeros(pred.qp.g.size), gains, plan, standin, cfg, j, e0, pred.blocks)
        for _ in range(3):
            z = rng.normal(scale=0.05, size=pred.qp.g.size)
            got = 0.5 * z @ pred.qp.H @ z + pred.qp.g @ z
            want = 0.5 * (_explicit_cost(z, gains, plan, standin, cfg, j, e0, pred.blocks) - base)
            assert got == pytest.approx(want, rel=1e-9, abs=1e-9 * base), (j, pred.blocks)


def test_sums_added_in_one_call_are_the_loops_to_the_bit():
    """condensed_qp adds a move's terms with one numpy call instead of a loop over its steps, and claims the same
    sums to the bit (so a run is unchanged, docs/performance.md): numpy reduces a stack's first axis in order.
    Terms of magnitudes 1e-8 .. 1e8, where any other order rounds differently, into a column slice of a matrix
    as condensed_qp does."""
    from twin.control.mpc import _add_in_order

    rng = np.random.default_rng(7)
    order_shows = 0
    for k in range(1, 12):
        terms = rng.normal(size=(k, 20, 3)) * 10.0 ** rng.integers(-8, 9, size=(k, 20, 3))
        G = rng.normal(size=(20, 12)) * 1e4
        want, backwards = G.copy(), G[:, 3:6].copy()
        for t in terms:
            want[:, 3:6] += t
        for t in terms[::-1]:
            backwards += t
        _add_in_order(G[:, 3:6], terms)
        assert G.tobytes() == want.tobytes(), k
        order_shows += not np.array_equal(backwards, want[:, 3:6])
    assert order_shows >= 5  # these sums do tell one order from another
