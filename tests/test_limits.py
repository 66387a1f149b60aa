"""Scenario limits and defaults derived from the furnace (twin/limits.py), and the scenario checked against them."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from twin.config import load_config, small_config
from twin.limits import default_limits, furnace_name, scenario_limits
from twin.scenario import Scenario, check, parse_oscillation, parse_reference, parse_scenario

# default_furnace.toml: L_h = 16 mm, eta_max = 50 mm, T_0 = 300 K, material tables up to 1300 K, TC4 (0.5, 0.5)
LOW = {"oscillation.eta_max": 0.03}  # a furnace whose stroke is shorter than the paper's 3 L_h = 48 mm


def test_limits_follow_the_furnace() -> None:
    default = scenario_limits(load_config("default"))
    assert default.furnace == "default"
    assert (default.amplitude.hi, default.amplitude.default) == (0.05, pytest.approx(0.048))  # 3 x 16 mm
    low = scenario_limits(small_config().with_overrides(LOW))
    assert (low.amplitude.hi, low.amplitude.default) == (0.03, 0.03)  # 3 L_h capped at eta_max
    fine = scenario_limits(small_config().with_overrides({"lamps.horizontal.pitch": 0.0125}))
    assert fine.amplitude.default == pytest.approx(0.0375)  # 3 x 12.5 mm, below eta_max: not capped
    assert (default.setpoint.lo, default.setpoint.hi, default.setpoint.default) == (300.0, 1300.0, 1100.0)
    warm = scenario_limits(small_config().with_overrides(
        {"specimen.initial_temperature": 350.0, "sensors.tc4": (0.375, 0.5), "sensors.noise": 2.5}))
    assert warm.setpoint.lo == 350.0 and "above 350 K" in str(warm.setpoint.problem(350.0))
    assert warm.tc4 == (0.375, 0.5) and warm.tc_noise.default == 2.5


def test_left_out_fields_take_the_furnace_defaults() -> None:
    low = scenario_limits(small_config().with_overrides(
        {**LOW, "sensors.tc4": (0.375, 0.5), "sensors.noise": 2.5}))
    s = parse_scenario({"oscillation": {"enabled": True}}, low)
    assert s.oscillation.amplitude == 0.03 and s.oscillation.enabled
    assert s.tc4 == (0.375, 0.5) and s.tc_noise == 2.5
    assert parse_scenario(None, low).oscillation.amplitude == 0.03
    given = parse_scenario({"oscillation": {"amplitude": 0.02}, "tc4": [0.5, 0.5], "tc_noise": 0.0}, low)
    assert (given.oscillation.amplitude, given.tc4, given.tc_noise) == (0.02, (0.5, 0.5), 0.0)  # what is given stays
    assert parse_oscillation({"enabled": True}, low).amplitude == 0.03


def _locs(exc: pytest.ExceptionInfo[ValidationError]) -> list[tuple]:
    return [e["loc"] for e in exc.value.errors()]


def test_a_check_names_the_field_and_the_bound() -> None:
    low = scenario_limits(small_config().with_overrides(LOW), "low_stroke")
    with pytest.raises(ValidationError) as exc:
        parse_scenario({"oscillation": {"enabled": True, "amplitude": 0.048}}, low)
    assert _locs(exc) == [("oscillation", "amplitude")]
    assert "at most 0.03 m (eta_max of furnace 'low_stroke'), got 0.048 m" in str(exc.value)
    assert parse_oscillation({"amplitude": 0.03}, low).amplitude == 0.03  # the bound itself is allowed
    with pytest.raises(ValidationError) as exc:
        parse_oscillation({"amplitude": 0.0301}, low)
    assert _locs(exc) == [("amplitude",)]
    with pytest.raises(ValidationError) as exc:
        parse_reference({"setpoint": 1300.5}, low)
    assert _locs(exc) == [("transition", "setpoint")] and "material tables" in str(exc.value)
    with pytest.raises(ValidationError, match="reachable range 300..1300 K"):
        parse_reference({"points": [[1.0, 1400.0]]}, low)
    # a scenario built without a furnace carries the default furnace's amplitude: the check names it
    with pytest.raises(ValidationError) as exc:
        check(Scenario(), low)
    assert _locs(exc) == [("oscillation", "amplitude")]
    check(Scenario(), default_limits())


def test_without_a_furnace_the_default_furnace_applies() -> None:
    """Scenario() and the models' documented defaults are the default furnace's (its file owns them)."""
    assert Scenario() == parse_scenario({}, scenario_limits(load_config("default")))
    with pytest.raises(ValidationError, match="eta_max of furnace 'default'"):
        Scenario.model_validate({"oscillation": {"amplitude": 0.051}})


def test_server_caps_and_json_shape() -> None:
    lim = default_limits().capped(max_duration_s=100.0, max_speed=10.0)
    assert (lim.duration.hi, lim.duration.default, lim.speed.hi) == (100.0, 100.0, 10.0)
    assert "this server's limit" in str(lim.duration.problem(200.0))
    j = lim.to_json()
    assert j["oscillation"]["amplitude"] == {"min": 0.0, "max": 0.05, "exclusive_min": False, "unit": "m",
                                             "default": pytest.approx(0.048)}
    assert j["reference"]["setpoint"]["exclusive_min"] is True and j["speed"]["default"] == "max"
    assert set(j) == {"reference", "duration", "oscillation", "tc4", "speed", "mismatch", "tc_noise", "seed", "truth",
                      "faults"}
    assert j["faults"]["targets"]["group"] == ["T1h", "T2h", "T3h", "T4h", "T1v", "T2v"]
    assert j["faults"]["derate"]["max"] == 1.0 and j["faults"]["kinds"]["tc"] == ["stuck", "drift", "offset", "dropout"]
    # issue 10: the honest truth is the default everywhere, the model's own plant one choice away
    assert j["truth"] == {"choices": ["independent", "shared"], "default": "independent"}


def test_furnace_name(tmp_path) -> None:
    assert furnace_name(load_config("banded")) == "banded"
    assert furnace_name(small_config()) == "custom"  # fewer rays: not a shipped furnace
    path = tmp_path / "low_stroke.toml"
    assert furnace_name(small_config(), path) == "low_stroke" and furnace_name(small_config(), "banded") == "banded"
