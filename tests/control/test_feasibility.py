"""Feasibility of a reference (twin.control.feasibility) on the twin's reduced model (small_config).

Oracles: the model itself stepped with constant inputs (u = 0, u = 1) for the hold range and the
heating limit, and the reference trajectory for what is asked."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.control.feasibility import (
    REFUSE_FRACTION,
    WARN_K,
    best_tracking,
    check_transition,
    hold_range,
    shortest_transition,
)
from twin.control.reference import coldest_surrounding, reference_trajectory
from twin.model.discrete import discrete_model
from twin.radiation import radiation_model
from twin.scenario import PointsReference, TransitionReference


@pytest.fixture(scope="module")
def setup():
    cfg = small_config()
    model = discrete_model(cfg, radiation_model(cfg), None)
    return cfg, model, hold_range(model, cfg)


def _simulate(model, u: float, T0: float, n: int) -> np.ndarray:
    theta, means = np.full(model.n, T0), [T0]
    for _ in range(n):
        theta = model.step(theta, np.full(model.m, u))
        means.append(float(model.c_m @ theta))
    return np.asarray(means)


def test_hold_range_is_the_lamps_off_and_full_power_steady_state(setup) -> None:
    cfg, model, (lo, hi) = setup
    # stepping the model for 2000 s with all lamps off (from 300 K) and at full power ends there
    off = _simulate(model, 0.0, 300.0, 20000)
    full = _simulate(model, 1.0, 300.0, 20000)
    assert lo == pytest.approx(off[-1], abs=0.05) and hi == pytest.approx(full[-1], abs=0.05)
    # the lamps-off state is far above the coldest surrounding (the warm holders and walls): a 301 K
    # setpoint "finishes" near 480 K, so the coldest surrounding is no lower bound
    assert lo > coldest_surrounding(cfg) + 100.0


def test_best_tracking_is_full_power_while_behind_and_the_reference_when_feasible(setup) -> None:
    cfg, model, _ = setup
    steep = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=1.2), 300.0)
    t, best = best_tracking(model, steep, np.full(model.n, 300.0), 0.0, 100)
    full = _simulate(model, 1.0, 300.0, 100)
    np.testing.assert_allclose(best, full, atol=1e-9)  # the reference is out of reach: every group at u_max
    paper = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=120.0), 300.0)
    t, best = best_tracking(model, paper, np.full(model.n, 300.0), 0.0, 2400)
    # on the reference, except at the slow start of the cubic where the warm surroundings heat the specimen
    # a little faster even with the lamps off (about 2.4 K above it: within the warning threshold)
    assert np.max(np.abs(best - paper(t))) < WARN_K


@pytest.mark.parametrize("spec, when", [
    (TransitionReference(setpoint=1100.0, t_E=1.2), 1.2),  # t_E = 1.2 s
    (PointsReference(points=[(0.0, 1300.0)]), 0.0),  # a 0 s step to 1300 K
    (PointsReference(points=[(1.0, 1300.0)]), 1.0),  # 300 -> 1300 K in 1 s
])
def test_absurd_references_are_refused_naming_the_time(setup, spec, when) -> None:
    cfg, model, hold = setup
    f = check_transition(model, cfg, spec, duration=240.0, hold=hold)
    assert f.verdict == "refuse"
    assert f.worst is not None and f.worst.t == pytest.approx(when, abs=0.15)
    assert f"at t = {f.worst.t:.1f} s" in f.messages[0] and "K short" in f.messages[0]
    assert abs(f.worst.shortfall) > REFUSE_FRACTION * (spec.setpoint - 300.0)


def test_a_steep_but_possible_reference_is_warned_with_time_and_shortfall(setup) -> None:
    cfg, model, hold = setup
    f = check_transition(model, cfg, TransitionReference(setpoint=1100.0, t_E=20.0), duration=240.0, hold=hold)
    assert f.verdict == "warn" and f.worst is not None
    # the oracle: the same greedy tracking computed by bisection on the uniform power per step (not by the
    # affine closed form), up to the worst time
    ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=20.0), 300.0)
    theta = np.full(model.n, 300.0)
    for j in range(int(round(f.worst.t / model.t_s))):
        target = float(ref((j + 1) * model.t_s))
        lo, hi = 0.0, 1.0
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if model.c_m @ model.step(theta, np.full(model.m, mid)) < target else (lo, mid)
        theta = model.step(theta, np.full(model.m, 0.5 * (lo + hi)))
    assert f.worst.shortfall == pytest.approx(float(ref(f.worst.t)) - float(model.c_m @ theta), abs=0.01)
    # and no input does better than full power from the start (the most heat the lamps can give)
    assert f.worst.shortfall >= float(ref(f.worst.t)) - _simulate(model, 1.0, 300.0, j + 1)[-1] - 1e-9
    assert f"{f.worst.shortfall:.0f} K short" in f.messages[0]
    assert any("shortest transition" in m for m in f.messages)
    assert check_transition(model, cfg, TransitionReference(setpoint=1100.0, t_E=120.0), duration=240.0,
                            hold=hold).verdict == "ok"  # the paper's run


def test_a_setpoint_below_the_lamps_off_state_is_refused(setup) -> None:
    cfg, model, hold = setup
    f = check_transition(model, cfg, TransitionReference(setpoint=301.0, t_E=120.0), duration=240.0, hold=hold)
    assert f.verdict == "refuse" and f"{hold[0]:.0f} K" in f.messages[0] and "lamps off" in f.messages[0]
    # just below it the mean ends a few K high: a warning, not a refusal
    near = check_transition(model, cfg, TransitionReference(setpoint=hold[0] - 20.0, t_E=120.0), duration=240.0,
                            hold=hold)
    assert near.verdict == "warn"


def test_points_after_the_end_of_the_run_are_warned(setup) -> None:
    cfg, model, hold = setup
    f = check_transition(model, cfg, PointsReference(points=[(60.0, 900.0), (300.0, 1100.0)]), duration=240.0,
                         hold=hold)
    assert f.verdict == "warn" and any("after the end of the run" in m for m in f.messages)


def test_a_live_change_is_judged_from_the_current_mean_and_time(setup) -> None:
    cfg, model, hold = setup
    spec = TransitionReference(setpoint=1000.0, t_E=30.0)
    at_900 = check_transition(model, cfg, spec, duration=240.0, T_initial=900.0, t_start=100.0, hold=hold)
    assert at_900.verdict == "ok"  # +100 K in 30 s from 900 K is easy
    at_300 = check_transition(model, cfg, TransitionReference(setpoint=1000.0, t_E=3.0), duration=240.0,
                              T_initial=300.0, t_start=100.0, hold=hold)
    assert at_300.verdict == "refuse" and 100.0 < at_300.worst.t <= 103.1  # named in run time


def test_shortest_transition_is_the_edge_of_feasibility(setup) -> None:
    cfg, model, hold = setup
    t_E = shortest_transition(model, cfg, 1100.0, 300.0, hold)
    assert t_E is not None and 15.0 < t_E < 60.0

    def gap(tE: float) -> float:
        ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=tE), 300.0)
        t, best = best_tracking(model, ref, np.full(model.n, 300.0), 0.0, int(1.2 * tE / model.t_s) + 1)
        return float(np.max(np.abs(ref(t) - best)))

    assert gap(t_E) <= WARN_K < gap(0.9 * t_E)  # followed at t_E, not 10 % faster (bisection to 5 %)
    assert shortest_transition(model, cfg, 2000.0, 300.0, hold) is None  # above what full power holds


def test_shortest_transition_ignores_a_start_that_runs_ahead(setup, small_radiation) -> None:
    """The mean runs ahead of a slow reference's start by itself (lamps off, warm holders and walls): with c_p(T) in
    the model by more than WARN_K.  That is no lag, so the shortest transition stays the edge of what full power can
    follow.  Found on `banded` with learnt, weaker lamps, where the check answered "no t_E can" for a reference
    that takes about 100 s; here the small furnace's model with lamps 40 % weaker (full-power hold 1247 K)."""
    from twin.control.plan_model import CapacityModel
    from twin.model.tables import Parameters

    cfg, _, _ = setup
    cp = CapacityModel.of(discrete_model(cfg, small_radiation, None, parameters=Parameters(lamp_efficiency=-0.4)),
                          cfg)
    hold = hold_range(cp, cfg)
    t_E = shortest_transition(cp, cfg, 1100.0, 300.0, hold)
    assert t_E is not None and 60.0 < t_E < 200.0

    def gap(tE: float) -> np.ndarray:
        ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=tE), 300.0)
        t, best = best_tracking(cp, ref, np.full(cp.n, 300.0), 0.0, int(1.2 * tE / cp.t_s) + 1)
        return np.asarray(ref(t) - best)

    assert np.min(gap(t_E)) < -WARN_K  # the premise: ahead of the reference's start by more than WARN_K
    assert np.max(gap(t_E)) <= WARN_K < np.max(gap(0.9 * t_E))  # no lag at t_E, a lag 10 % faster


def test_the_plans_reserve_is_named(setup) -> None:
    """A transition the lamps follow at full power but not within the plan's share (``feedforward_limit``):
    the check says the feedback will spend its reserve, and when.  Within the share: no such sentence."""
    cfg, model, hold = setup
    shortest = shortest_transition(model, cfg, 1100.0, 300.0, hold)
    assert shortest is not None
    spec = TransitionReference(setpoint=1100.0, t_E=1.3 * shortest)
    assert check_transition(model, cfg, spec, duration=3 * spec.t_E, hold=hold, limit=1.0).verdict == "ok"
    capped = check_transition(model, cfg, spec, duration=3 * spec.t_E, hold=hold, limit=0.6)
    assert capped.verdict == "warn" and any("reserve" in m and "60%" in m for m in capped.messages)
    assert check_transition(model, cfg, TransitionReference(setpoint=1100.0, t_E=120.0), duration=240.0,
                            hold=hold, limit=0.85).verdict == "ok"  # the paper's run leaves the reserve alone


def test_learnt_parameters_move_the_verdict(setup, small_radiation) -> None:
    """On the model with lamps learnt 50 % weaker (small furnace: full-power hold 1430 K -> 1187 K), 1250 K is out
    of reach, and the reachable trajectory (``T_best``) ends below it."""
    from twin.model.tables import Parameters

    cfg, model, hold = setup
    weak = discrete_model(cfg, small_radiation, None, parameters=Parameters(lamp_efficiency=-0.5))
    weak_hold = hold_range(weak, cfg)
    setpoint = 1250.0
    assert weak_hold[1] < setpoint - 50.0 < hold[1] - 100.0
    spec = TransitionReference(setpoint=setpoint, t_E=300.0)
    assert check_transition(model, cfg, spec, duration=600.0, hold=hold, T_initial=900.0).verdict == "ok"
    f = check_transition(weak, cfg, spec, duration=600.0, hold=weak_hold, T_initial=900.0)
    assert f.verdict in ("warn", "refuse") and f.T_best[-1] < setpoint - 10.0
    assert f"{weak_hold[1]:.0f} K" in " ".join(f.messages)
