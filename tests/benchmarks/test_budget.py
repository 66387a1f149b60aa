"""``python -m benchmarks.budget``: the parts of a sample add up to the step, the parts inside parts are not
counted twice, and every part it names is measured (a renamed method would drop out of the budget silently)."""

from __future__ import annotations

import pytest

from benchmarks.budget import FLOOR, MPC_CONDENSE, NESTED, PARTS, sample_budget
from twin.config import small_config


def test_the_parts_add_up_to_the_step(small_radiation) -> None:
    budget = sample_budget(small_config(), small_radiation, duration=1.0)
    step = budget["step"]
    assert step["calls_per_sample"] == 1.0
    top = [label for label, _, _ in PARTS] + ["other (loop's own work)"]
    # the top-level parts and the loop's own work are the whole step; the nested ones lie inside theirs
    assert sum(budget[label]["share"] for label in top) == pytest.approx(1.0, abs=1e-9)
    assert budget["other (loop's own work)"]["share"] > 0.0
    assert budget[FLOOR]["mean_ms"] <= budget["EKF predict (14), (15)"]["mean_ms"]
    assert budget[MPC_CONDENSE]["mean_ms"] <= budget["controller (MPC / LQG)"]["mean_ms"]
    for label, path, _ in NESTED:  # the estimator's inside parts, each measured every sample (the small furnace's
        if path.startswith("estimator"):  # feedback is the LQG: no QP to time)
            assert budget[label]["calls_per_sample"] >= 1.0, label
    for label in ("EKF update (13)", "EKF predict (14), (15)", "controller (MPC / LQG)", "divergence guard"):
        assert budget[label]["calls_per_sample"] >= 1.0, label


def test_a_controller_adopted_by_a_replan_is_timed_too(small_radiation) -> None:
    """A re-plan installs a new controller object (``ClosedLoop.adopt``): its calls belong to the controller's part,
    not to "other" (before, the default run's budget counted the controller on 0.57 of its samples)."""
    from benchmarks.budget import time_adopted_controllers
    from twin.runs.loop import ClosedLoop
    from twin.scenario import Scenario

    loop = ClosedLoop(small_config(), Scenario(duration=1.0), small_radiation)
    try:
        calls: list[float] = []
        time_adopted_controllers(loop, calls)
        loop.step()
        assert calls == []  # the first controller is the caller's to wrap
        old = loop.controller
        loop.adopt(loop.changes.current, motion_changed=False, fresh_integrator=False)
        assert loop.controller is not old
        loop.step()
        loop.step()
        assert len(calls) == 2 and all(c > 0.0 for c in calls)
    finally:
        loop.close()


def test_the_ceiling_sums_the_result_parts_medians(small_radiation) -> None:
    """The ceiling is t_s over the sum of the result parts' medians (each part counted once), so it lies above the
    rtf of the median step, whose parts include them."""
    from benchmarks.budget import CEILING, RESULT_PARTS, format_budget

    cfg = small_config()
    budget = sample_budget(cfg, small_radiation, duration=1.0)
    present = [label for label in RESULT_PARTS if label in budget]
    assert len(present) >= 6  # the small furnace's LQG has no QP to time
    floor = sum(budget[label]["median_ms"] for label in present)
    c = budget[CEILING]
    assert c["median_ms"] == pytest.approx(floor) and c["rtf"] == pytest.approx(1e3 * cfg.sampling.t_s / floor)
    assert c["rtf"] > c["rtf_median_step"] == pytest.approx(1e3 * cfg.sampling.t_s / budget["step"]["median_ms"])
    assert f"at most {c['rtf']:.0f}" in format_budget(budget)
