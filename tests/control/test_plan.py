"""The feedforward plan's bookkeeping (twin.control.plan) and the OCP's time scales (twin.control.ocp_grid).

Every expected number below is worked by hand from the definitions in the docstrings; no IPOPT
solve is needed (tests/control/test_feedforward.py covers the OCP itself).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from twin.control.ocp_grid import _fastest_rate, mean_time_constant
from twin.control.plan import FeedforwardError, FeedforwardPlan, plain_status, saturation, simulate


def _plan(t0: float = 10.0, n: int = 4) -> FeedforwardPlan:
    t = t0 + 0.1 * np.arange(n + 1)
    u = np.arange(n, dtype=float)[:, None] * np.array([[1.0, 10.0]])  # u_ff,j = [j, 10 j]
    theta = 100.0 * np.arange(n + 1, dtype=float)[:, None] * np.ones((1, 3))
    return FeedforwardPlan(t=t, u_ff=u, theta_ref=theta, T_ref=1000.0 + np.arange(n + 1), T_mean=np.zeros(n + 1),
                           status="by hand", iterations=0, solve_s=0.0, success=True,
                           warm={"t_knots": np.array([10.0, 11.0, 12.0, 13.0]), "v": np.array([5.0, 6.0, 7.0])})


def test_index_of_a_run_time_is_the_nearest_sample() -> None:
    plan = _plan()
    assert plan.t0 == 10.0 and plan.t_s == pytest.approx(0.1) and plan.n_steps == 4
    # (t - t0) / t_s rounded: 0.24 s -> 2.4 -> 2, 0.26 s -> 2.6 -> 3, beyond the horizon allowed
    assert [plan.index_at(t) for t in (10.0, 10.24, 10.26, 10.4, 11.0)] == [0, 2, 3, 4, 10]


def test_samples_hold_the_last_values_beyond_the_horizon() -> None:
    plan = _plan()
    u, theta, T = plan.sample(2)
    assert u.tolist() == [2.0, 20.0] and theta.tolist() == [200.0] * 3 and T == 1002.0
    # u_ff has N = 4 entries (0..3), theta_ref and T_ref N + 1 (0..4)
    for j in (4, 5, 100):
        u, theta, T = plan.sample(j)
        assert u.tolist() == [3.0, 30.0] and theta.tolist() == [400.0] * 3 and T == 1004.0
    with pytest.raises(IndexError):
        plan.sample(-1)


def test_v_is_held_over_each_ocp_interval_and_outside() -> None:
    plan = _plan()  # as the OCP stores them: K + 1 knot times (interval ends included), K values
    t = np.array([9.0, 10.0, 10.5, 11.0, 11.999, 12.0, 13.0, 50.0])
    np.testing.assert_array_equal(plan.v_at(t), [5.0, 5.0, 5.0, 6.0, 6.0, 7.0, 7.0, 7.0])


def test_max_mean_error_is_the_largest_tracking_gap() -> None:
    plan = _plan()
    assert plan.max_mean_error == 1004.0  # T_mean = 0, T_ref = 1000..1004


@dataclass
class _Linear:
    """theta+ = theta + t_s (A theta + B u): an affine model with a known Jacobian."""

    A: np.ndarray
    B: np.ndarray
    t_s: float = 0.5

    @property
    def n(self) -> int:
        return self.A.shape[0]

    @property
    def c_m(self) -> np.ndarray:
        return np.full(self.n, 1.0 / self.n)

    def step(self, theta, u):
        return np.asarray(theta) + self.t_s * (self.A @ np.asarray(theta) + self.B @ np.asarray(u))

    def jac_theta(self, theta, u):
        return np.eye(self.n) + self.t_s * self.A


def test_simulate_steps_the_model_from_the_initial_state() -> None:
    # theta+ = theta + 0.5 (-theta + 2 u) = 0.5 theta + u; from 1 with u = 1, 2, 0: 1.5, 2.75, 1.375
    model = _Linear(np.array([[-1.0]]), np.array([[2.0]]))
    np.testing.assert_allclose(simulate(model, [1.0], [[1.0], [2.0], [0.0]])[:, 0], [1.0, 1.5, 2.75, 1.375])


def test_saturation_clips_to_the_unit_interval() -> None:
    np.testing.assert_array_equal(saturation([-0.5, 0.0, 0.3, 1.0, 1.7]), [0.0, 0.0, 0.3, 1.0, 1.0])


def test_saturation_gives_double_precision_fractions() -> None:
    """u_ff = sat(v u_c) stays float64 when v or u_c come in single precision (no float32 plan)."""
    got = saturation(np.array([-0.5, 0.3, 1.7], dtype=np.float32))
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, [0.0, np.float32(0.3), 1.0])


def test_simulate_hands_the_model_double_precision_inputs() -> None:
    """The model's step gets float64 inputs (the DiscreteDynamics protocol), also for lists of ints or
    float32 inputs: a compiled model need not convert them."""
    seen = []

    class _Recording(_Linear):
        def step(self, theta, u):
            seen.append(np.asarray(u).dtype)
            return super().step(theta, u)

    model = _Recording(np.array([[-1.0]]), np.array([[2.0]]))
    np.testing.assert_allclose(simulate(model, [1], [[1], [2], [0]])[:, 0], [1.0, 1.5, 2.75, 1.375])
    simulate(model, np.array([1.0]), np.array([[0.5]], dtype=np.float32))
    assert seen == [np.float64] * 4


def test_plain_status_words() -> None:
    """IPOPT's statuses in words; another status with underscores in lower-case words; one without
    underscores (the name of a plan's source) as it is."""
    assert plain_status("Solve_Succeeded") == "solved"
    assert plain_status("Infeasible_Problem_Detected") == "no plan meets the constraints, the closest one is used"
    assert plain_status("User_Requested_Stop") == "user requested stop"
    assert plain_status("Paper") == "Paper" and plain_status("by hand") == "by hand"


def test_a_shifted_plan_starts_later_with_its_knots() -> None:
    """shifted(dt): the sample times and the OCP's knot times move by dt, nothing else changes, and the
    plan it was made from is left as it was."""
    plan = _plan()
    later = plan.shifted(2.5)
    np.testing.assert_array_equal(later.t, plan.t + 2.5)
    np.testing.assert_array_equal(later.warm["t_knots"], [12.5, 13.5, 14.5, 15.5])
    np.testing.assert_array_equal(later.warm["v"], plan.warm["v"])
    np.testing.assert_array_equal(later.u_ff, plan.u_ff)
    np.testing.assert_array_equal(later.T_ref, plan.T_ref)
    assert later.status == plan.status and set(later.warm) == {"t_knots", "v"}
    np.testing.assert_array_equal(plan.t, 10.0 + 0.1 * np.arange(5))
    np.testing.assert_array_equal(plan.warm["t_knots"], [10.0, 11.0, 12.0, 13.0])
    np.testing.assert_array_equal(later.v_at([12.0, 14.4, 14.6]), [5.0, 6.0, 7.0])  # v moved with the knots
    # knots kept as a list of whole seconds (e.g. read back from JSON) become float run times
    listed = FeedforwardPlan(**{**plan.__dict__, "warm": {"t_knots": [10, 11], "v": [5.0]}}).shifted(3)
    assert listed.warm["t_knots"].dtype == np.float64 and listed.warm["t_knots"].tolist() == [13.0, 14.0]
    # a plan without knots (not parametrized) shifts its times only
    plain = FeedforwardPlan(**{**plan.__dict__, "warm": {}}).shifted(1.0)
    assert plain.warm == {} and plain.t[0] == 11.0


def test_feedforward_error_keeps_the_solver_status() -> None:
    err = FeedforwardError("failed", "Maximum_Iterations_Exceeded")
    assert err.status == "Maximum_Iterations_Exceeded" and str(err) == "failed"


def test_mean_time_constant_is_the_inverse_loss_rate() -> None:
    """tau = 1 / (-c_m^T J 1): conduction (a Laplacian, L 1 = 0) does not change how a uniform rise decays."""
    n, a, k = 5, 0.04, 0.7  # 1/s: loss rate to the surroundings, conduction between neighbours
    L = k * (np.diag(np.ones(n - 1), 1) + np.diag(np.ones(n - 1), -1) - np.diag([1.0] + [2.0] * (n - 2) + [1.0]))
    model = _Linear(-a * np.eye(n) + L, np.ones((n, 1)))
    assert mean_time_constant(model, np.zeros(n), [0.0]) == pytest.approx(1.0 / a, rel=1e-12)
    # no losses at all: the time constant is capped (1 / 1e-6 s), not infinite or negative
    assert mean_time_constant(_Linear(L, np.ones((n, 1))), np.zeros(n), [0.0]) == pytest.approx(1e6)


@dataclass
class _Radiating(_Linear):
    """theta+ = theta + t_s (A theta - k theta^4 + B u): the Jacobian depends on the state."""

    k: float = 1e-11

    def jac_theta(self, theta, u):
        return np.eye(self.n) + self.t_s * (self.A - np.diag(4.0 * self.k * np.asarray(theta) ** 3))


def test_time_scales_are_taken_at_the_given_state() -> None:
    # uniform 1000 K: the loss rate is a + 4 k T^3 = 0.04 + 0.04 1/s, tau = 12.5 s (by hand)
    model = _Radiating(-0.04 * np.eye(3), np.ones((3, 1)))
    assert mean_time_constant(model, np.full(3, 1000.0), [0.0]) == pytest.approx(12.5, rel=1e-12)
    # the fastest rate of the diagonal Jacobian: the hottest node, 0.04 + 4e-11 * 1500^3 = 0.175 1/s
    assert _fastest_rate(model, np.array([1000.0, 1500.0, 500.0]), np.zeros(1)) == pytest.approx(0.175, rel=1e-12)


def test_fastest_rate_is_the_spectral_radius_of_the_continuous_jacobian() -> None:
    # J = [[-1, 2], [-2, -1]] has the eigenvalues -1 +- 2i: |lambda| = sqrt(5)
    model = _Linear(np.array([[-1.0, 2.0], [-2.0, -1.0]]), np.zeros((2, 1)))
    assert _fastest_rate(model, np.zeros(2), np.zeros(1)) == pytest.approx(np.sqrt(5.0), rel=1e-12)
    assert _fastest_rate(_Linear(np.diag([-0.1, -2.5, -0.7]), np.zeros((3, 1))), np.zeros(3), np.zeros(1)) \
        == pytest.approx(2.5, rel=1e-12)


def test_transition_end_prefers_the_references_own_end() -> None:
    from twin.control.ocp_grid import transition_end
    from twin.control.reference import reference_trajectory
    from twin.scenario import TransitionReference

    ref = reference_trajectory(TransitionReference(setpoint=900.0, t_E=30.05), 300.0)
    assert transition_end(ref, 0.0, 0.1) == 30.05  # not the 30.1 s a scan on the 0.1 s grid would find


def test_transition_end_of_a_callable_is_the_first_sample_after_it_stops_moving() -> None:
    from twin.control.ocp_grid import MAX_REFERENCE_S, transition_end

    # a ramp from t0 = 2 s that stops at 2.55 s: moving at 2.0 .. 2.5 s, constant from 2.6 s on (0.1 s grid)
    assert transition_end(lambda t: np.minimum(np.asarray(t) - 2.0, 0.55), 2.0, 0.1) == pytest.approx(2.6)
    # a reference that moves until the end of the longest scan (MAX_REFERENCE_S after t0)
    def slow(t):
        return 1000.0 + np.minimum(np.asarray(t, float), MAX_REFERENCE_S)

    assert transition_end(slow, 0.0, 0.1) == pytest.approx(MAX_REFERENCE_S)
    # the threshold is exactly 1e-9 x max(1 K, |final|): a change of exactly that is not motion
    assert transition_end(lambda t: 1e-9 * (np.asarray(t) < 5.0), 0.0, 0.1) == 0.0
    # ... and the scale is the final value, not an early one: 0 K at the start, then 5e-7 K below 1000 K
    def late(t):
        t = np.asarray(t, float)
        return np.where(t < 1.0, 0.0, np.where(t < 20.0, 1000.0 - 5e-7, 1000.0))

    assert transition_end(late, 0.0, 0.1) == pytest.approx(1.0)
    # a change far below 1e-9 relative of the final value is not motion (round-off of a held value)
    assert transition_end(lambda t: 1000.0 + 1e-10 * (np.asarray(t) < 5.0), 0.0, 0.1) == 0.0
    # ... but a change of 1e-6 K at 1000 K is (1e-9 x 1000 K = 1e-6 K is the threshold: strictly above)
    assert transition_end(lambda t: 1000.0 + 2e-6 * (np.asarray(t) < 5.0), 0.0, 0.1) == pytest.approx(5.0)
    assert transition_end(lambda t: 1000.0 + 0.5e-6 * (np.asarray(t) < 5.0), 0.0, 0.1) == 0.0
    # the threshold is relative to the final value, at least 1e-9 K
    assert transition_end(lambda t: 2e-9 * (np.asarray(t) < 5.0), 0.0, 0.1) == pytest.approx(5.0)
