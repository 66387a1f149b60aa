"""The OpenAPI schemas with this server's bounds: its furnace's limits and its settings' caps.

The request models (``twin.scenario``) check the bounds that depend on the furnace (setpoint, reference
temperatures, oscillation amplitude, lamp-group names) and on the server (run length, speed) against the
limits given at validation; their static JSON schema cannot know them.  This fills them into the served
schema, so a client that keeps to ``/openapi.json`` sends what the server accepts (what JSON Schema can say:
strictly increasing reference times and a fault kind's target type are checked only by the server).

>>> from twin.limits import default_limits
>>> osc = {"title": "OscillationSpec", "properties": {"amplitude": {"minimum": 0.0}}}
>>> spec = apply_limits({"components": {"schemas": {"OscillationSpec": osc}}}, default_limits())
>>> osc["properties"]["amplitude"]
{'minimum': 0.0, 'maximum': 0.05}
"""

from __future__ import annotations

from typing import Any

from backend.api.study_schema import tighten_study
from twin.limits import FAULT_VALUE_RANGE, GROUP_FAULT_KINDS, TC_FAULT_KINDS, TC_NAMES, Range, ScenarioLimits

#: Scenario: a furnace over OPC UA runs in real time (speed 1, its default there) and takes no injected faults
OPCUA_REAL_TIME: dict[str, Any] = {
    "if": {"required": ["plant"], "properties": {
        "plant": {"type": "object", "required": ["kind"], "properties": {"kind": {"const": "opcua"}}}}},
    "then": {"properties": {"speed": {"const": 1}, "faults": {"maxItems": 0}}},
}


def _bounds(schema: dict[str, Any], r: Range) -> None:
    """Set ``schema``'s bounds to the range ``r`` (an open lower end as exclusiveMinimum)."""
    schema.pop("exclusiveMinimum", None)
    schema.pop("minimum", None)
    schema["exclusiveMinimum" if r.lo_open else "minimum"] = r.lo
    schema["maximum"] = r.hi


def _fault_kinds(groups: tuple[str, ...]) -> list[dict[str, Any]]:
    """One schema per fault kind: its targets (TCs or lamp groups) and its value (a bounded number, or none)."""
    kinds = []
    for kind in (*TC_FAULT_KINDS, *GROUP_FAULT_KINDS):
        targets = TC_NAMES if kind in TC_FAULT_KINDS else groups
        r = FAULT_VALUE_RANGE.get(kind)
        value: dict[str, Any] = {"type": "null"}
        if r is not None:
            value = {"type": "number"}
            _bounds(value, r)
        kinds.append({"properties": {"kind": {"const": kind}, "target": {"enum": list(targets)}, "value": value},
                      "required": ["kind", "target", *(["value"] if r is not None else [])]})
    return kinds


def _by_title(node: Any, found: dict[str, list[dict[str, Any]]]) -> None:
    """Every object schema in ``node`` (components and bodies FastAPI wrote inline), by its title."""
    if isinstance(node, dict):
        if isinstance(node.get("title"), str) and isinstance(node.get("properties"), dict):
            found.setdefault(node["title"], []).append(node)
        for value in node.values():
            _by_title(value, found)
    elif isinstance(node, list):
        for value in node:
            _by_title(value, found)


def apply_limits(spec: dict[str, Any], limits: ScenarioLimits, furnaces: tuple[str, ...] = ()) -> dict[str, Any]:
    """Write ``limits`` (a furnace's, capped by a server's settings: ``ScenarioLimits.capped``) into the
    request schemas of ``spec``, and ``furnaces`` (the names a study may give) if any; returns ``spec``."""
    found: dict[str, list[dict[str, Any]]] = {}
    _by_title(spec, found)

    def props(name: str) -> list[dict[str, Any]]:
        return [s["properties"] for s in found.get(name, [])]

    for p in props("OscillationSpec"):
        if "amplitude" in p:
            _bounds(p["amplitude"], limits.amplitude)
    for p in props("TransitionReference"):
        if "setpoint" in p:
            _bounds(p["setpoint"], limits.setpoint)
    for p in props("PointsReference"):
        points = p.get("points", {}).get("items", {}).get("prefixItems")
        if points is not None and len(points) == 2:
            _bounds(points[0], limits.point_time)
            _bounds(points[1], limits.point_temperature)
    for p in props("Scenario"):
        if "duration" in p:
            _bounds(p["duration"], limits.duration)
            p["duration"]["default"] = limits.duration.default
        for option in p.get("speed", {}).get("anyOf", []):
            if option.get("type") == "number":
                _bounds(option, limits.speed)
        if "tc_noise" in p:
            _bounds(p["tc_noise"], limits.tc_noise)
    for fault in found.get("FaultSpec", []):
        if "target" in fault["properties"] and limits.groups:
            fault["properties"]["target"]["enum"] = [*TC_NAMES, *limits.groups]
            fault["oneOf"] = _fault_kinds(limits.groups)
    for p in props("StudySpec"):
        if "furnace" in p and furnaces:
            p["furnace"].pop("anyOf", None)
            p["furnace"].update({"anyOf": [{"enum": list(furnaces)}, {"type": "null"}]})
    for scenario in found.get("Scenario", []):
        scenario.setdefault("allOf", []).append(OPCUA_REAL_TIME)
    if "Scenario" in spec.get("components", {}).get("schemas", {}):
        for study in found.get("StudySpec", []):
            tighten_study(spec, study)  # after the bounds above: the grid's values carry them
    return spec
