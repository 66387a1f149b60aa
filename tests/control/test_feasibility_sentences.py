"""The feasibility check's verdicts, times and sentences, exactly, on a furnace whose answers are known in closed form.

:mod:`test_feasibility` judges the twin's own reduced model; here the model is one node, linear, with two lamp
groups (``OneNode``): theta+ = a theta + (1 - a) T_amb + (b / 2) (u_1 + u_2).  It holds between T_amb (lamps off)
and T_amb + b / (1 - a) (full power), and from theta_0 at full power (lamps off) it is at
T_full + (theta_0 - T_full) a^j (T_amb + (theta_0 - T_amb) a^j) after j samples.  While the reference runs ahead
of full power (or below lamps off) the best the furnace can do *is* that closed form, so the shortfall, its time,
the first time it exceeds WARN_K and the time it is caught up again are known without the code under test, and
the sentences a user reads are checked word for word.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.control.feasibility import (
    REFUSE_MIN_K,
    WARN_K,
    Feasibility,
    Shortfall,
    _describe,
    best_tracking,
    check_reference,
    check_transition,
    hold_range,
    reserve_note,
    shortest_transition,
)
from twin.scenario import PointsReference, TransitionReference

T_S, AA, T_AMB, B = 0.1, 0.999, 500.0, 1.0  # s; per sample; K; K per sample at full power (both groups)
T_FULL = T_AMB + B / (1.0 - AA)  # 1500 K


class OneNode:
    """The :class:`twin.model.dynamics.DiscreteDynamics` a one-node linear furnace has (module docstring)."""

    n, m, t_s = 1, 2, T_S
    c_m = np.ones(1)
    W = np.ones((1, 1))

    def __init__(self, b: float = B) -> None:
        self.b = b

    def step(self, theta, u):
        return AA * np.asarray(theta, float) + (1.0 - AA) * T_AMB + 0.5 * self.b * float(np.sum(u))

    def jac_theta(self, theta, u):
        return np.array([[AA]])

    def jac_u(self, theta, u):
        return np.full((1, 2), 0.5 * self.b)


class Ramps:
    """A piecewise-linear reference through ``points`` (t, T), constant before the first and after the last."""

    def __init__(self, *points: tuple[float, float]) -> None:
        self.tp, self.Tp = np.array([p[0] for p in points]), np.array([p[1] for p in points])
        self.t_end, self.T_final = float(self.tp[-1]), float(self.Tp[-1])

    def __call__(self, t):
        return np.interp(np.asarray(t, float), self.tp, self.Tp)


def full_power(theta0: float, j):
    return T_FULL + (theta0 - T_FULL) * AA ** np.asarray(j, float)


def lamps_off(theta0: float, j):
    return T_AMB + (theta0 - T_AMB) * AA ** np.asarray(j, float)


@pytest.fixture(scope="module")
def model():
    return OneNode()


@pytest.fixture(scope="module")
def cfg():
    from twin.config import small_config

    return small_config()


def test_the_hold_range_is_lamps_off_and_full_power(model, cfg) -> None:
    assert hold_range(model, cfg) == pytest.approx((T_AMB, T_FULL), abs=1e-6)


def test_best_tracking_is_the_closed_form_while_behind_and_on_the_reference_after(model) -> None:
    ref = Ramps((0.0, 600.0), (30.0, 900.0))  # 1 K per sample; full power heats 0.9 K per sample at 600 K
    t, best = best_tracking(model, ref, np.array([600.0]), 0.0, 600)
    assert t == pytest.approx(T_S * np.arange(601))
    j = np.arange(301)
    assert best[:301] == pytest.approx(full_power(600.0, j), abs=1e-9)
    caught = int(np.argmax(full_power(600.0, np.arange(601)) >= 900.0))  # full power would pass 900 K here
    assert best[caught:] == pytest.approx(900.0, abs=1e-9)  # then exactly on the reference (s < 1)
    # capped at half power: 0.5 - 0.001 (theta - 500) K per sample, the closed form with T_full = 1000 K
    t, half = best_tracking(model, ref, np.array([600.0]), 0.0, 300, s_max=0.5)
    assert half == pytest.approx(1000.0 + (600.0 - 1000.0) * AA ** np.arange(301), abs=1e-9)
    # and never below lamps off: a reference far below is followed by the lamps-off closed form
    t, low = best_tracking(model, Ramps((0.0, 300.0)), np.array([900.0]), 0.0, 100)
    assert low == pytest.approx(lamps_off(900.0, np.arange(101)), abs=1e-9)
    # a furnace whose lamps do nothing (t_s B 1 = 0) is simply left at s_max
    t, dead = best_tracking(OneNode(b=0.0), ref, np.array([600.0]), 0.0, 10)
    assert dead == pytest.approx(lamps_off(600.0, np.arange(11)), abs=1e-9)


def _first(mask: np.ndarray) -> int:
    return int(np.flatnonzero(mask)[0])


def test_a_ramp_faster_than_full_power_is_warned_with_its_times_and_shortfall(model, cfg) -> None:
    """600 -> 900 K in 30 s (1 K per sample against at most 0.9): the mean falls furthest behind when the ramp
    ends (t = 30 s), departs by more than WARN_K earlier, and catches up once full power passes 897 K."""
    ref = Ramps((0.0, 600.0), (30.0, 900.0))
    f = check_reference(model, cfg, ref, T_initial=600.0, t_start=0.0, t_end=100.0, hold=(T_AMB, T_FULL))
    j = np.arange(1001)
    gap = ref(T_S * j) - full_power(600.0, j)
    first = _first(gap > WARN_K) * T_S
    catch = _first((j > 300) & (gap <= WARN_K)) * T_S
    short = 900.0 - full_power(600.0, 300)
    assert f.verdict == "warn"  # 67 K: above WARN_K, below half the 300 K excursion
    assert f.worst == Shortfall(pytest.approx(30.0), 900.0, pytest.approx(full_power(600.0, 300)))
    assert f.worst.shortfall == pytest.approx(short)
    assert f.first_t == pytest.approx(first) and f.hold_range == (T_AMB, T_FULL)
    assert f.messages == (
        f"at t = 30.0 s the reference asks for 900 K, but even at full power the fillet mean reaches only "
        f"{full_power(600.0, 300):.0f} K by then ({short:.0f} K short)",
        f"the fillet mean departs from the reference from t = {first:.1f} s on",
        f"it catches up at t = {catch:.1f} s",
    )
    assert f.t == pytest.approx(T_S * j) and f.T_best[:301] == pytest.approx(full_power(600.0, j[:301]))


def test_a_step_departs_where_it_is_worst_and_says_so_once(model, cfg) -> None:
    """600 -> 1000 K between two samples (5.0 and 5.1 s): the shortfall is largest at its first sample, so no
    separate "departs from" sentence; full power catches up at the closed form's 997 K."""
    # (the mean is held on the reference before the step, so full power starts from 600 K at 5.0 s)
    ref = Ramps((0.0, 600.0), (5.0, 600.0), (5.05, 1000.0))
    f = check_reference(model, cfg, ref, T_initial=600.0, t_start=0.0, t_end=200.0, hold=(T_AMB, T_FULL))
    j = np.arange(2001)
    held_then_full = np.where(j <= 50, 600.0, full_power(600.0, j - 50))  # held at 600 K (s = 0.1), then u = 1
    catch = _first((j > 51) & (held_then_full >= 1000.0 - WARN_K)) * T_S
    assert f.worst.t == pytest.approx(5.1) and f.first_t == pytest.approx(5.1)
    assert f.messages[1:] == (f"it catches up at t = {catch:.1f} s",)


def test_a_ramp_that_full_power_follows_is_ok_without_words(model, cfg) -> None:
    ref = Ramps((0.0, 600.0), (100.0, 850.0))  # 0.25 K per sample; full power gives 0.65 or more up to 850 K
    f = check_reference(model, cfg, ref, T_initial=600.0, t_start=0.0, t_end=150.0, hold=(T_AMB, T_FULL))
    assert (f.verdict, f.messages, f.first_t) == ("ok", (), None)
    assert np.max(np.abs(ref(f.t) - f.T_best)) < 1e-9 and f.worst is None  # on the reference throughout


def test_a_final_value_above_full_power_is_refused_as_not_holdable(model, cfg) -> None:
    """600 -> 1600 K in 100 s, run to 300 s: 1600 K is 100 K above what full power holds (1500 K)."""
    ref = Ramps((0.0, 600.0), (100.0, 1600.0))
    f = check_reference(model, cfg, ref, T_initial=600.0, t_start=0.0, t_end=300.0, hold=(T_AMB, T_FULL))
    j = np.arange(3001)
    gap = ref(T_S * j) - full_power(600.0, j)
    short = 1600.0 - full_power(600.0, 1000)
    assert short < 0.5 * 1000.0  # not refused for its size (half the excursion): for the value it cannot hold
    assert f.verdict == "refuse" and f.worst.t == pytest.approx(100.0)
    assert f.messages == (
        f"at t = 100.0 s the reference asks for 1600 K; this furnace holds at most 1500 K with every group at "
        f"full power ({short:.0f} K short)",
        f"the fillet mean departs from the reference from t = {_first(gap > WARN_K) * T_S:.1f} s on",
        "it does not catch up before the end of the run",
    )


def test_a_final_value_just_within_reach_of_the_refusal_is_only_warned(model, cfg) -> None:
    """REFUSE_MIN_K is the bar for a value the furnace cannot hold: 1540 K (40 K above full power) is warned."""
    ref = Ramps((0.0, 1400.0), (200.0, T_FULL + REFUSE_MIN_K - 10.0))
    f = check_reference(model, cfg, ref, T_initial=1400.0, t_start=0.0, t_end=400.0, hold=(T_AMB, T_FULL))
    assert f.verdict == "warn"
    assert f.messages[0].endswith(f"this furnace holds at most 1500 K with every group at full power "
                                  f"({f.worst.shortfall:.0f} K short)")


def test_the_value_that_cannot_be_held_is_named_when_the_worst_is_on_the_way(model, cfg) -> None:
    """A steep start (600 -> 1400 K in 10 s) then slowly to 1560 K by 200 s: the mean is furthest behind at 10 s,
    and the last value, above what full power holds, gets a sentence of its own."""
    ref = Ramps((0.0, 600.0), (10.0, 1400.0), (200.0, 1560.0))
    f = check_reference(model, cfg, ref, T_initial=600.0, t_start=0.0, t_end=300.0, hold=(T_AMB, T_FULL))
    assert f.verdict == "refuse" and f.worst.t == pytest.approx(10.0)
    first = _first(ref(T_S * np.arange(101)) - full_power(600.0, np.arange(101)) > WARN_K) * T_S
    assert f.messages == (
        f"at t = 10.0 s the reference asks for 1400 K, but even at full power the fillet mean reaches only "
        f"{full_power(600.0, 100):.0f} K by then ({1400.0 - full_power(600.0, 100):.0f} K short)",
        "its last value, 1560 K from t = 200.0 s, cannot be held: this furnace cannot hold the fillet mean above "
        "1500 K (full power)",
        f"the fillet mean departs from the reference from t = {first:.1f} s on",
        "it does not catch up before the end of the run",
    )


def test_a_final_value_below_lamps_off_is_refused_and_the_warm_surroundings_named(model, cfg) -> None:
    """900 -> 400 K in 50 s: 100 K below the lamps-off steady state (500 K)."""
    ref = Ramps((0.0, 900.0), (50.0, 400.0))
    f = check_reference(model, cfg, ref, T_initial=900.0, t_start=0.0, t_end=200.0, hold=(T_AMB, T_FULL))
    above = lamps_off(900.0, 500) - 400.0
    assert f.verdict == "refuse" and f.worst.t == pytest.approx(50.0)
    assert f.worst.shortfall == pytest.approx(-above)
    assert f.messages[0] == (
        "at t = 50.0 s the reference asks for 400 K, but this furnace cannot hold the fillet mean below 500 K (its "
        "steady state with the lamps off: the warm holders and walls heat the specimen); by then it is "
        f"{above:.0f} K above the reference")
    assert f.messages[-1] == "it does not catch up before the end of the run"


def test_cooling_faster_than_lamps_off_is_judged_by_the_excursion(model, cfg) -> None:
    """900 -> 700 K in 10 s (2 K per sample against at most 0.4 with the lamps off): 162 K above the reference
    at 10 s is more than half the 200 K excursion and more than REFUSE_MIN_K: refused.  Either bar alone is a
    warning: 900 -> 500 K in 100 s ends 147 K high (over 50 K, under half of 400 K), 900 -> 870 K in 0.5 s about
    28 K (over half of 30 K, under 50 K)."""
    ref = Ramps((0.0, 900.0), (10.0, 700.0))
    f = check_reference(model, cfg, ref, T_initial=900.0, t_start=0.0, t_end=100.0, hold=(T_AMB, T_FULL))
    j = np.arange(1001)
    gap = ref(T_S * j) - lamps_off(900.0, j)
    above = lamps_off(900.0, 100) - 700.0
    assert f.verdict == "refuse" and above > 0.5 * 200.0
    assert f.messages == (
        f"at t = 10.0 s the reference asks for 700 K, but even with the lamps off the fillet mean is at "
        f"{lamps_off(900.0, 100):.0f} K by then, {above:.0f} K above the reference",
        f"the fillet mean departs from the reference from t = {_first(gap < -WARN_K) * T_S:.1f} s on",
        f"it catches up at t = {_first((j > 100) & (gap >= -WARN_K)) * T_S:.1f} s",
    )
    slow = check_reference(model, cfg, Ramps((0.0, 900.0), (100.0, 500.0)), T_initial=900.0, t_start=0.0,
                           t_end=200.0, hold=(T_AMB, T_FULL))
    assert slow.verdict == "warn" and REFUSE_MIN_K < -slow.worst.shortfall < 0.5 * 400.0
    assert slow.worst.shortfall == pytest.approx(500.0 - lamps_off(900.0, 1000))
    small = check_reference(model, cfg, Ramps((0.0, 900.0), (0.5, 870.0)), T_initial=900.0, t_start=0.0,
                            t_end=100.0, hold=(T_AMB, T_FULL))
    assert small.verdict == "warn" and 0.5 * 30.0 < -small.worst.shortfall < REFUSE_MIN_K


def test_the_sentence_for_each_kind_of_shortfall() -> None:
    """:func:`_describe` at the edges of its cases (hold range 500-1500 K, WARN_K = 3 K)."""
    hold = (500.0, 1500.0)
    hot = Shortfall(12.0, 1503.5, 1400.0)
    assert _describe(hot, hold, True) == ("at t = 12.0 s the reference asks for 1504 K; this furnace holds at most "
                                          "1500 K with every group at full power (104 K short)")
    edge = Shortfall(12.0, 1503.0, 1400.0)  # not above 1500 + WARN_K: the way there
    assert _describe(edge, hold, True) == ("at t = 12.0 s the reference asks for 1503 K, but even at full power the "
                                           "fillet mean reaches only 1400 K by then (103 K short)")
    assert _describe(hot, hold, False) == _describe(edge, hold, False).replace("1503 K", "1504 K").replace(
        "103 K", "104 K")
    cold = Shortfall(40.0, 496.5, 520.0)
    assert _describe(cold, hold, True).startswith("at t = 40.0 s the reference asks for 496 K, but this furnace "
                                                  "cannot hold the fillet mean below 500 K")
    assert _describe(cold, hold, True).endswith("by then it is 24 K above the reference")
    near = Shortfall(40.0, 497.0, 503.0)  # T_ref not below 500 - WARN_K; T_best within WARN_K of lamps off
    assert _describe(near, hold, True) == ("at t = 40.0 s the reference asks for 497 K, but even with the lamps off "
                                           "the fillet mean is at 503 K by then (the warm holders and walls heat "
                                           "it), 6 K above the reference")
    warm = Shortfall(40.0, 600.0, 503.5)
    assert _describe(Shortfall(40.0, 497.0, 503.5), hold, False) == (
        "at t = 40.0 s the reference asks for 497 K, but even with the lamps off the fillet mean is at 504 K by then, "
        "6 K above the reference")
    assert warm.shortfall > 0  # a hot shortfall is never described as a cold one
    assert "full power" in _describe(warm, hold, False)


def test_the_verdict_as_json_is_decimated_to_max_points(model, cfg) -> None:
    ref = Ramps((0.0, 600.0), (30.0, 900.0))
    f = check_reference(model, cfg, ref, T_initial=600.0, t_start=0.0, t_end=100.0, hold=(T_AMB, T_FULL))
    out = f.to_json(max_points=300)  # 1001 points: every 4th (ceil(1001 / 300))
    assert out["verdict"] == "warn" and out["messages"] == list(f.messages)
    assert out["worst"] == {"t": f.worst.t, "T_ref": 900.0, "T_best": f.worst.T_best,
                            "shortfall": f.worst.shortfall}
    assert out["first_t"] == f.first_t and out["hold_range"] == [T_AMB, T_FULL]
    assert out["best"]["t"] == pytest.approx(f.t[::4].tolist()) and len(out["best"]["t"]) == 251
    assert out["best"]["T"] == pytest.approx(f.T_best[::4].tolist())
    assert len(f.to_json()["best"]["t"]) == 334  # default 400: every 3rd
    assert len(f.to_json(max_points=2000)["best"]["t"]) == 1001
    empty = Feasibility("ok", (), None, None, (T_AMB, T_FULL)).to_json()
    assert empty == {"verdict": "ok", "messages": [], "worst": None, "first_t": None, "hold_range": [T_AMB, T_FULL],
                     "best": {"t": [], "T": []}}


def _capped(ref: Ramps, theta0: float, n: int, s_max: float) -> np.ndarray:
    """The best mean with at most s_max of full power, stepped here (scalar: s from the next reference value)."""
    theta, out = theta0, [theta0]
    for j in range(n):
        free = AA * theta + (1.0 - AA) * T_AMB
        s = min(max((float(ref((j + 1) * T_S)) - free) / B, 0.0), s_max)
        theta = free + s * B
        out.append(theta)
    return np.asarray(out)


def test_the_plans_reserve_sentence_names_the_lag_and_its_time(model, cfg) -> None:
    """600 -> 900 K in 100 s (0.3 K per sample): full power follows it; with half of it (0.5 - 0.001 (theta - 500)
    K per sample, under 0.3 above 700 K) the mean falls behind, most at the end of the ramp."""
    ref = Ramps((0.0, 600.0), (100.0, 900.0))
    full = check_reference(model, cfg, ref, T_initial=600.0, t_start=0.0, t_end=200.0, hold=(T_AMB, T_FULL))
    assert full.verdict == "ok"
    capped = _capped(ref, 600.0, 2000, 0.5)
    gap = ref(T_S * np.arange(2001)) - capped
    k = int(np.argmax(gap))
    note = reserve_note(model, ref, 600.0, 0.0, 200.0, 0.5, full)
    assert note == (f"the plan may use 50% of each group's power (the rest is the feedback's reserve): with that the "
                    f"fillet mean would fall {gap[k]:.0f} K behind at t = {k * T_S:.1f} s, so the feedback spends its "
                    "reserve on the plan there")
    assert k * T_S == pytest.approx(100.0)
    assert reserve_note(model, ref, 600.0, 0.0, 200.0, 1.0, full) is None  # the whole power is the plan's
    assert reserve_note(model, ref, 600.0, 0.0, 200.0, 0.9, full) is None  # 0.9: never more than WARN_K behind
    refused = Feasibility("refuse", ("x",), full.worst, 1.0, full.hold_range, full.t, full.T_best)
    assert reserve_note(model, ref, 600.0, 0.0, 200.0, 0.5, refused) is None  # refused anyway: nothing to add


def test_a_live_change_is_checked_from_its_start_in_run_time(model, cfg) -> None:
    """The same ramp from t = 50 s: every time in the sentences moves by 50 s."""
    f0 = check_reference(model, cfg, Ramps((0.0, 600.0), (30.0, 900.0)), T_initial=600.0, t_start=0.0,
                         t_end=100.0, hold=(T_AMB, T_FULL))
    f50 = check_reference(model, cfg, Ramps((50.0, 600.0), (80.0, 900.0)), T_initial=600.0, t_start=50.0,
                          t_end=150.0, hold=(T_AMB, T_FULL))
    assert f50.worst.t == pytest.approx(80.0) and f50.first_t == pytest.approx(f0.first_t + 50.0)
    assert f50.T_best == pytest.approx(f0.T_best) and len(f50.t) == len(f0.t)
    for m0, m50 in zip(f0.messages, f50.messages, strict=True):
        times0 = [float(w) for w in m0.replace(",", " ").split() if w.replace(".", "").isdigit() and "." in w]
        times50 = [float(w) for w in m50.replace(",", " ").split() if w.replace(".", "").isdigit() and "." in w]
        assert times50 == pytest.approx([x + 50.0 for x in times0])


def test_check_transition_adds_what_a_user_can_change(model, cfg) -> None:
    """The paper's transition (eq. 36 shape) to 1100 K, too fast for this furnace: the shortest t_E it follows is
    named; points after the run's end are named; a reference the plan's share cannot follow becomes a warning."""
    fast = TransitionReference(setpoint=1100.0, t_E=60.0)
    f = check_transition(model, cfg, fast, duration=400.0, T_initial=600.0, hold=(T_AMB, T_FULL), limit=1.0)
    shortest = shortest_transition(model, cfg, 1100.0, 600.0, (T_AMB, T_FULL))
    assert shortest is not None and shortest > 60.0
    assert f.verdict in ("warn", "refuse")
    assert f.messages[-1] == (f"the shortest transition to 1100 K this furnace can follow takes about "
                              f"{shortest:.0f} s (t_E)")
    slow = TransitionReference(setpoint=1100.0, t_E=math.ceil(shortest * 1.1))
    ok = check_transition(model, cfg, slow, duration=800.0, T_initial=600.0, hold=(T_AMB, T_FULL), limit=1.0)
    assert (ok.verdict, ok.messages) == ("ok", ())
    capped = check_transition(model, cfg, slow, duration=800.0, T_initial=600.0, hold=(T_AMB, T_FULL), limit=0.7)
    assert capped.verdict == "warn" and len(capped.messages) == 1 and capped.messages[0].startswith(
        "the plan may use 70% of each group's power")
    late = PointsReference(points=[(10.0, 620.0), (120.0, 700.0)])
    p = check_transition(model, cfg, late, duration=100.0, T_initial=600.0, hold=(T_AMB, T_FULL), limit=1.0)
    assert p.verdict == "warn" and p.messages == (
        "the last reference point (t = 120 s) lies after the end of the run (100 s): the run ends before the "
        "reference does",)
    live = check_transition(model, cfg, late, duration=100.0, T_initial=600.0, t_start=5.0, hold=(T_AMB, T_FULL),
                            limit=1.0)
    assert "(t = 125 s)" in live.messages[-1]
    inside = check_transition(model, cfg, PointsReference(points=[(10.0, 620.0), (100.0, 700.0)]), duration=100.0,
                              T_initial=600.0, hold=(T_AMB, T_FULL), limit=1.0)
    assert (inside.verdict, inside.messages) == ("ok", ())
