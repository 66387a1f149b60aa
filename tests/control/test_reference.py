"""Reference trajectories (twin.control.reference): C1 transition, C1 points, validation."""

from __future__ import annotations

import numpy as np
import pytest
from controller_standin import make_standin
from hypothesis import given
from hypothesis import strategies as st
from pydantic import ValidationError

from twin.config import small_config
from twin.control.reference import (
    ReferenceError,
    coldest_surrounding,
    reachable_range,
    reference_trajectory,
    steady_state,
)
from twin.scenario import PointsReference, TransitionReference


def _c1_jumps(ref, knots, h=1e-6):
    """Largest jump of value and of slope across the knots (one-sided finite differences)."""
    jv, js = 0.0, 0.0
    for k in knots:
        left = ref(np.array([k - 2 * h, k - h, k]))
        right = ref(np.array([k, k + h, k + 2 * h]))
        jv = max(jv, abs(left[-1] - right[0]))
        s_left = (3 * left[2] - 4 * left[1] + left[0]) / (2 * h)  # second-order one-sided
        s_right = (-3 * right[0] + 4 * right[1] - right[2]) / (2 * h)
        js = max(js, abs(s_left - s_right))
    return jv, js


def test_transition_endpoints_midpoint_and_rate():
    ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=120.0), 300.0)
    assert ref(np.array([0.0]))[0] == 300.0 and ref(np.array([120.0]))[0] == 1100.0
    assert ref(np.array([-5.0, 500.0])).tolist() == [300.0, 1100.0]  # constant outside
    # cubic step 3 s^2 - 2 s^3 at s = 1/2 is 1/2 and at s = 1/4 is 5/32 (hand computation)
    assert ref(np.array([60.0]))[0] == pytest.approx(700.0, rel=1e-14)
    assert ref(np.array([30.0]))[0] == pytest.approx(300.0 + 800.0 * 5 / 32, rel=1e-14)
    # the maximum rate 1.5 (T_E - T_0) / t_E = 10 K/s is reached at t_E / 2
    assert ref.rate(np.array([60.0]))[0] == pytest.approx(10.0, rel=1e-12)
    assert ref.transition_time == 120.0


def test_transition_is_c1_and_monotone():
    ref = reference_trajectory(TransitionReference(setpoint=900.0, t_E=50.0), 350.0, t_start=10.0)
    jv, js = _c1_jumps(ref, [10.0, 60.0])
    # finite-difference slopes with h = 1e-6 s on ~1000 K values: round-off ~ 1e-13 * 1000 / 1e-6 = 1e-4 K/s
    assert jv < 1e-9 and js < 1e-3
    t = np.linspace(0, 100, 2001)
    assert np.all(np.diff(ref(t)) >= 0)
    assert ref(np.array([9.0]))[0] == 350.0  # before t_start: the initial mean


def test_points_pass_through_and_are_c1():
    spec = PointsReference(points=[(20.0, 600.0), (60.0, 1000.0), (80.0, 1000.0), (120.0, 900.0)])
    ref = reference_trajectory(spec, 300.0, t_start=5.0)
    # through every point (times relative to t_start) and the initial mean at t_start
    np.testing.assert_allclose(ref(np.array([5.0, 25.0, 65.0, 85.0, 125.0])),
                               [300.0, 600.0, 1000.0, 1000.0, 900.0], rtol=1e-14)
    jv, js = _c1_jumps(ref, [5.0, 25.0, 65.0, 85.0, 125.0])
    assert jv < 1e-9 and js < 1e-3  # as above: finite-difference round-off
    assert ref(np.array([400.0]))[0] == 900.0 and ref.t_end == 125.0
    # monotone between monotone data (Fritsch-Carlson): no overshoot above 1000 K on the plateau
    t = np.linspace(5, 125, 4001)
    assert ref(t).max() <= 1000.0 + 1e-9
    assert np.all(np.diff(ref(np.linspace(5, 65, 1001))) >= -1e-12)


def test_single_point_at_zero_is_constant():
    ref = reference_trajectory(PointsReference(points=[(0.0, 800.0)]), 300.0)
    assert ref(np.array([0.0, 10.0])).tolist() == [800.0, 800.0]
    assert ref.rate(np.array([1.0]))[0] == 0.0


def test_non_increasing_times_are_rejected():
    with pytest.raises(ValidationError, match="strictly increasing"):
        PointsReference(points=[(10.0, 500.0), (10.0, 600.0)])
    # a spec that bypassed validation still gets a clear error from the reference itself
    for points in ([(10.0, 500.0), (5.0, 600.0)], [(10.0, 500.0), (10.0, 600.0)]):  # decreasing, repeated
        bad = PointsReference.model_construct(points=points)
        with pytest.raises(ReferenceError, match="strictly increasing"):
            reference_trajectory(bad, 300.0)


def test_unreachable_temperatures_are_rejected():
    with pytest.raises(ReferenceError, match="unreachable"):
        reference_trajectory(TransitionReference(setpoint=1200.0), 300.0, T_range=(320.0, 1150.0))
    with pytest.raises(ReferenceError, match="unreachable"):
        reference_trajectory(PointsReference(points=[(10.0, 310.0)]), 400.0, T_range=(320.0, 1150.0))
    with pytest.raises(ReferenceError):
        reference_trajectory(TransitionReference(), float("nan"))


def test_coldest_surrounding_is_config_minimum():
    cfg = small_config()
    lowest = min(cfg.housing.temperature, cfg.reflector.temperature, cfg.inert_gas.temperature_top,
                 cfg.holders.temperature_upper, cfg.holders.temperature_lower, cfg.inert_gas.temperature_bottom)
    assert coldest_surrounding(cfg) == lowest


def test_steady_state_and_reachable_range_on_linear_oracle():
    # with radiation switched off the stand-in is linear: (I - F_theta) theta = t_s B u solves it exactly
    model = make_standin()
    model.k_r = np.zeros(model.n)
    model.A_c = model.A_c - 0.05 * np.eye(model.n)  # losses to 0 K so a steady state exists
    u = np.full(model.m, 0.7)
    exact = np.linalg.solve(-model.A_c, model.B @ u)
    theta = steady_state(model, u, np.full(model.n, 500.0))
    np.testing.assert_allclose(theta, exact, rtol=1e-10)
    cfg = small_config()
    lo, hi = reachable_range(model, cfg)
    exact_full = np.linalg.solve(-model.A_c, model.B @ np.ones(model.m))
    assert lo == coldest_surrounding(cfg)
    assert hi == pytest.approx(float(model.c_m @ exact_full), rel=1e-10)


def test_steady_state_of_nonlinear_standin_is_fixed_point():
    model = make_standin()
    u = np.full(model.m, 0.5)
    theta = steady_state(model, u, np.full(model.n, 700.0))
    # Newton tolerance 1e-6 K; one more step of the model moves it by t_s |f| << 1e-6 K
    assert np.max(np.abs(model.step(theta, u) - theta)) < 1e-6


SURROUNDINGS = ("housing.temperature", "reflector.temperature", "holders.temperature_upper",
                "holders.temperature_lower", "inert_gas.temperature_top", "inert_gas.temperature_bottom")


@pytest.mark.parametrize("field", SURROUNDINGS)
def test_each_surrounding_can_be_the_coldest(field):
    cfg = small_config().with_overrides({field: 251.0})  # colder than every other surface of the furnace
    assert coldest_surrounding(cfg) == 251.0


def test_reachable_range_is_closed_and_named_in_the_error():
    lo, hi = 320.0, 1150.0
    # the ends themselves are reachable
    assert reference_trajectory(TransitionReference(setpoint=hi), 400.0, T_range=(lo, hi)).T_final == hi
    assert reference_trajectory(PointsReference(points=[(10.0, lo)]), 400.0, T_range=(lo, hi)).T_final == lo
    with pytest.raises(ReferenceError, match="setpoint 1150.1 K is unreachable"):
        reference_trajectory(TransitionReference(setpoint=1150.1), 400.0, T_range=(lo, hi))
    with pytest.raises(ReferenceError, match="reference point temperature 319.9 K is unreachable"):
        reference_trajectory(PointsReference(points=[(10.0, 319.9)]), 400.0, T_range=(lo, hi))


def test_initial_temperature_and_start_time_are_checked():
    for bad in (0.0, -5.0, float("inf")):
        with pytest.raises(ReferenceError, match="initial mean temperature"):
            reference_trajectory(TransitionReference(), bad)
    assert reference_trajectory(TransitionReference(), 0.5).T_initial == 0.5  # any positive kelvin
    for bad in (-1.0, float("nan")):
        with pytest.raises(ReferenceError, match="t_start"):
            reference_trajectory(TransitionReference(), 300.0, t_start=bad)


def test_points_starting_after_the_start_rise_from_the_initial_mean_at_once():
    # first point at 0.5 s: the curve starts at T_initial at t_start and is already moving at 0.25 s
    ref = reference_trajectory(PointsReference(points=[(0.5, 700.0)]), 300.0, t_start=4.0)
    assert ref.t_start == 4.0 and ref(np.array([4.0]))[0] == 300.0
    assert 300.0 < ref(np.array([4.25]))[0] < 700.0
    assert ref(np.array([4.5]))[0] == 700.0
    # a single point at 0 s is a step to a constant: no transition at all
    flat = reference_trajectory(PointsReference(points=[(0.0, 800.0)]), 300.0, t_start=7.0)
    assert (flat.t_start, flat.t_end, flat.T_initial, flat.T_final) == (7.0, 7.0, 800.0, 800.0)


def test_rate_is_zero_outside_the_transition_as_floats():
    ref = reference_trajectory(TransitionReference(setpoint=900.0, t_E=50.0), 350.0, t_start=10.0)
    r = ref.rate(np.array([0.0, 10.0, 60.0, 100.0]))
    assert r.dtype == np.float64 and r.tolist() == [0.0, 0.0, 0.0, 0.0]


# ------------------------------------------------------------------ properties (hypothesis)
@st.composite
def _monotone_points(draw):
    """Strictly increasing times (s, relative) and monotone temperatures (K), rising or falling."""
    n = draw(st.integers(1, 6))
    gaps = draw(st.lists(st.floats(1.0, 60.0), min_size=n, max_size=n))
    t0 = draw(st.sampled_from([0.0, 5.0]))
    times = (t0 + np.cumsum(gaps) - gaps[0]).tolist()
    steps = draw(st.lists(st.floats(0.0, 300.0), min_size=n, max_size=n))
    sign = draw(st.sampled_from([1.0, -1.0]))
    T_initial = draw(st.floats(260.0, 1290.0))
    # within the scenario's admissible 300..1300 K, T_0 to the top of the material tables (clipping keeps the
    # data monotone)
    temps = np.clip(T_initial + sign * np.cumsum(steps), 300.0, 1290.0).tolist()
    return list(zip(times, temps, strict=True)), T_initial, draw(st.floats(0.0, 100.0))


@given(_monotone_points())
def test_points_reference_is_monotone_between_monotone_points_and_c1(case) -> None:
    points, T_initial, t_start = case
    ref = reference_trajectory(PointsReference(points=points), T_initial, t_start=t_start)
    knots = [t_start + t for t, _ in points]
    temps = np.array([T for _, T in points])
    np.testing.assert_allclose(ref(np.array(knots)), temps, rtol=1e-13)  # through every point
    t = np.linspace(t_start - 10.0, knots[-1] + 10.0, 4001)
    T = ref(t)
    d = np.diff(T)
    rising = temps[-1] >= T_initial
    tol = 1e-9 * np.abs(T).max()
    assert (d >= -tol).all() if rising else (d <= tol).all()  # monotone data: no overshoot (Fritsch-Carlson)
    lo, hi = min(T_initial, temps.min()), max(T_initial, temps.max())
    assert T.min() >= lo - tol and T.max() <= hi + tol
    # C1: no jump of value or slope at any knot, including the joins with the constants at both ends
    gap = min([b - a for a, b in zip(knots, knots[1:], strict=False)] + [1.0])
    jv, js = _c1_jumps(ref, sorted({t_start, *knots}), h=1e-6 * gap)
    slope_scale = (hi - lo) / gap + 1.0
    assert jv < 1e-9 * hi and js < 1e-3 * slope_scale
    # the rate is the derivative of the curve (central differences, O(h^2))
    tm = np.linspace(t_start, knots[-1], 50)[1:-1]
    h = 1e-4 * gap
    np.testing.assert_allclose(ref.rate(tm), (ref(tm + h) - ref(tm - h)) / (2 * h), atol=1e-4 * slope_scale)


@given(st.floats(260.0, 1290.0), st.floats(301.0, 1300.0), st.floats(2.0, 600.0), st.floats(0.0, 500.0))
def test_transition_is_monotone_c1_and_the_cubic_step(T0, T_E, t_E, t_start) -> None:
    ref = reference_trajectory(TransitionReference(setpoint=T_E, t_E=t_E), T0, t_start=t_start)
    s = np.linspace(0.0, 1.0, 101)
    # the cubic Hermite step T0 + (T_E - T0)(3 s^2 - 2 s^3) (module docstring), by its formula
    np.testing.assert_allclose(ref(t_start + s * t_E), T0 + (T_E - T0) * (3 * s**2 - 2 * s**3),
                               rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(ref.rate(t_start + s[1:-1] * t_E),
                               (T_E - T0) * 6 * s[1:-1] * (1 - s[1:-1]) / t_E, rtol=1e-9, atol=1e-12)
    d = np.diff(ref(np.linspace(t_start - 1.0, t_start + t_E + 1.0, 1001)))
    assert (np.sign(T_E - T0) * d >= -1e-9 * max(T0, T_E)).all()
    jv, js = _c1_jumps(ref, [t_start, t_start + t_E], h=1e-6 * t_E)
    assert jv < 1e-9 * max(T0, T_E) and js < 1e-3 * (abs(T_E - T0) / t_E + 1.0)


def test_steady_state_that_does_not_converge_is_a_reference_error():
    model = make_standin()
    u = np.full(model.m, 0.5)
    with pytest.raises(ReferenceError, match="steady state of the model did not converge in 1 iterations"):
        steady_state(model, u, np.full(model.n, 300.0), max_iter=1)
    # from a cold start far below the fixed point Newton's steps are capped at 500 K and still converge
    theta = steady_state(model, u, np.full(model.n, 300.0))
    assert np.max(np.abs(model.step(theta, u) - theta)) < 1e-6


def test_rate_is_exactly_zero_from_the_end_of_the_transition_on():
    """dT_ref/dt is 0 outside (t_start, t_end), also at t_end itself, where the spline's own slope carries
    round-off (7e-15 K/s for this transition): a settled reference does not move at all."""
    ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=120.0), 300.0, t_start=7.3)
    assert ref._spline.derivative()(ref.t_end) != 0.0  # the round-off the rate must not show
    r = ref.rate(np.array([ref.t_end, ref.t_end + 1.0, 1e4]))
    assert r.tolist() == [0.0, 0.0, 0.0]
    assert ref.rate(np.array([ref.t_start + 60.0]))[0] == pytest.approx(1.5 * 800.0 / 120.0, rel=1e-12)


def test_a_constant_reference_at_integer_times_is_float():
    """A one-point reference is constant: at integer run times it is its temperature as a float (not
    truncated to an integer), its rate float zeros."""
    ref = reference_trajectory(PointsReference(points=[(0.0, 1100.5)]), 300.0)
    got = ref(np.array([0, 10, 100]))
    assert got.dtype == np.float64 and got.tolist() == [1100.5] * 3
    rate = ref.rate(np.array([0, 10]))
    assert rate.dtype == np.float64 and rate.tolist() == [0.0, 0.0]


class _Linear1:
    """theta+ = theta + 0.5 (b - theta), b = 1000 + 100 u: one node, fixed point b, Newton's step b - theta."""

    n, m = 1, 1
    c_m = np.ones(1)

    def step(self, theta, u):
        return theta + 0.5 * (1000.0 + 100.0 * u[0] - theta)

    def jac_theta(self, theta, u):
        return np.full((1, 1), 0.5)


def test_newton_steps_of_the_steady_state_are_capped_at_500_K():
    """From 1502 K below the fixed point the steps are 500, 500, 500, 2 K and a last check: 5 iterations
    (4 fail); an uncapped or a 501 K cap would need fewer.  The default limit is 50 iterations: 24,502 K
    below (49 capped steps, a 2 K one and the check: 51) is too far, 24,002 K (50) is not."""
    model, u = _Linear1(), np.array([0.0])
    with pytest.raises(ReferenceError, match="in 4 iterations"):
        steady_state(model, u, np.array([1000.0 - 1502.0]), max_iter=4)
    assert steady_state(model, u, np.array([1000.0 - 1502.0]), max_iter=5)[0] == pytest.approx(1000.0, abs=1e-9)
    with pytest.raises(ReferenceError, match="in 50 iterations"):
        steady_state(model, u, np.array([1000.0 - 24502.0]))
    assert steady_state(model, u, np.array([1000.0 - 24002.0]))[0] == pytest.approx(1000.0, abs=1e-9)


def test_steady_state_of_a_model_whose_jacobian_depends_on_u():
    """theta+ = theta + 0.1 (1000 u - (1 + u) theta): fixed point 1000 u / (1 + u); dF/dtheta = 1 - 0.1 (1 + u)
    needs the same u as F (a model need not be input-affine).  The model gets u as float64 also when it
    is given as a list of ints."""
    seen = []

    class _Bilinear:
        n, m = 1, 1
        c_m = np.ones(1)

        def step(self, theta, u):
            seen.append(np.asarray(u).dtype)
            return theta + 0.1 * (1000.0 * u[0] - (1.0 + u[0]) * theta)

        def jac_theta(self, theta, u):
            seen.append(np.asarray(u).dtype)
            return np.full((1, 1), 1.0 - 0.1 * (1.0 + u[0]))

    theta = steady_state(_Bilinear(), [3], np.array([300.0]))
    assert theta[0] == pytest.approx(750.0, rel=1e-12)
    assert seen and all(dt == np.float64 for dt in seen)
