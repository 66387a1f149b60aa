"""The scenario contract of product.md: defaults, both reference forms, clear validation errors."""

import json

import pytest
from pydantic import ValidationError

from twin.scenario import PointsReference, Scenario, TransitionReference


def test_defaults_are_the_product_contract():
    s = json.loads(Scenario().to_json())
    # the optional fields of product.md ("More scenario fields"), with their defaults
    assert s.pop("estimator") == {"motion": "position_aware", "calibrate": True, "shadow": None}
    assert s == {
        "reference": {"setpoint": 1100.0, "t_E": 120.0},
        "duration": 240.0,
        "oscillation": {"enabled": False, "amplitude": 0.048, "period": 18.0},
        "tc4": [0.5, 0.5],
        "speed": "max",
        "mismatch": {"emissivity": 0.0, "alpha": 0.0, "lamp_efficiency": 0.0},
        "tc_noise": 1.0,
        "seed": 0,
        "faults": [],
        "truth": "independent",  # product.md: the furnace file's [truth] by default; "shared" to compare
        "plant": {"kind": "simulated"},  # product.md, "More scenario fields"
        "control": {"feedback": None, "plan_parameters": None},  # issue 26: [control] feedback, nominal plan
    }
    with pytest.raises(ValidationError, match="truth"):
        Scenario.model_validate({"truth": "model"})


def test_reference_forms_are_told_apart():
    assert isinstance(Scenario.model_validate({"reference": {"setpoint": 1000}}).reference, TransitionReference)
    ref = Scenario.model_validate({"reference": {"points": [[0, 300], [60, 900], [100, 1000]]}}).reference
    assert isinstance(ref, PointsReference) and ref.setpoint == 1000 and ref.t_E == 100


@pytest.mark.parametrize(
    ("body", "needle"),
    [
        ({"reference": {"points": [[0, 300], [0, 900]]}}, "strictly increasing"),
        ({"reference": {"points": [[0, 300], [10, 2500]]}}, "reachable"),
        ({"reference": {"setpoint": 5000}}, "reference.transition.setpoint"),
        ({"speed": 0}, "speed"),
        ({"speed": "fast"}, "speed"),
        ({"tc4": [0.5, 1.2]}, "tc4"),
        ({"duration": 1e6}, "duration"),
        ({"oscillation": {"amplitude": 0.2}}, "oscillation.amplitude"),
        ({"colour": "red"}, "colour"),
    ],
)
def test_bad_scenarios_say_what_is_wrong(body, needle):
    with pytest.raises(ValidationError) as err:
        Scenario.model_validate(body)
    assert needle in str(err.value)
