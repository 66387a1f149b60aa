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
