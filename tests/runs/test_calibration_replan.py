"""When the controller's model follows the calibration (twin.runs.estimators.RunEstimators.calibration_due).

Oracle: the rule as the module and default_furnace.toml state it (threshold 0.02, interval 30 s): re-plan only
when the controller follows, the reference holds still, a parameter is known to better than the threshold
and has moved by more than it since the plan, at most once per interval.
"""

from __future__ import annotations

import pytest

from twin.config import small_config
from twin.model.tables import Parameters, model_tables
from twin.runs.estimators import RunEstimators
from twin.scenario import EstimatorSpec

CFG = small_config()


def _run(small_radiation, follows: bool, value: float, sigma: float) -> RunEstimators:
    cfg = CFG.with_overrides({"calibration.controller_follows": follows})
    run = RunEstimators(EstimatorSpec(motion="position_aware", calibrate=True), model_tables(cfg, small_radiation),
                        None, cfg, 300.0)
    run.primary.calibration = lambda: {"lamp_efficiency": {"value": value, "sigma": sigma},  # type: ignore[method-assign]
                                       "emissivity": {"value": 0.0, "sigma": sigma}}
    return run


def test_defaults_leave_the_controller_on_the_nominal_model(small_radiation) -> None:
    assert CFG.calibration.controller_follows is False  # measured worse (default_furnace.toml)
    run = _run(small_radiation, follows=False, value=-0.1, sigma=0.005)
    assert run.calibration_due(200.0, Parameters(), holding=True) is None


def test_follows_only_while_the_reference_holds(small_radiation) -> None:
    run = _run(small_radiation, follows=True, value=-0.1, sigma=0.005)
    assert run.calibration_due(100.0, Parameters(), holding=False) is None  # heating: not identifiable
    said = run.calibration_due(130.0, Parameters(), holding=True)
    assert said is not None and "lamp_efficiency -10.0 %" in said
    assert run.calibration_due(150.0, Parameters(), holding=True) is None  # within 30 s of the last one
    assert run.calibration_due(160.0, Parameters(), holding=True) is not None


@pytest.mark.parametrize(("value", "sigma", "planned", "due"), [
    (-0.1, 0.03, 0.0, False),   # moved, but not known to better than 2 %
    (-0.1, 0.005, -0.09, False),  # known, but within 2 % of the plan's
    (-0.1, 0.005, -0.07, True),
])
def test_threshold_on_sigma_and_move(small_radiation, value, sigma, planned, due) -> None:
    run = _run(small_radiation, follows=True, value=value, sigma=sigma)
    got = run.calibration_due(200.0, Parameters(lamp_efficiency=planned), holding=True)
    assert (got is not None) is due
