"""The study body's schema as strict as its validation: the grid's field paths and their values, the base.

``StudySpec`` (``twin.studies.spec``) holds the grid as ``field path -> values`` and the base as a free
object, so its own JSON schema takes any key; the server then refuses a path that names no scenario field
(``check_paths``).  schemathesis read that as "a schema-valid request rejected" (``{"grid": {"": [[]]}}``).
Here the served schema lists every path a grid may vary (each scenario field and group, and the fields of
each member of a union such as ``reference.t_E``), each with at least one value of that field's schema, never a
field together with a field inside it, "seed" only when a Monte Carlo block does not draw seeds itself, and
the base is a ``Scenario``.  What JSON Schema cannot say stays the server's: a union member's field (say
``reference.t_E``) is valid only when the base's reference is that member.

>>> spec = {"components": {"schemas": {
...     "Scenario": {"properties": {"seed": {"type": "integer"}, "oscillation": {"$ref": "#/components/schemas/O"}}},
...     "O": {"properties": {"period": {"type": "number"}}}}}}
>>> sorted(scenario_paths(spec))
['oscillation', 'oscillation.period', 'seed']
"""

from __future__ import annotations

import copy
from typing import Any

REF = "#/components/schemas/"


#: StudySpec: a grid that varies "seed" needs a Monte Carlo block without seeds of its own ("base")
SEED_VARIED_ONCE: dict[str, Any] = {
    "if": {"required": ["monte_carlo"],
           "properties": {"monte_carlo": {"type": "object", "properties": {"seeds": {"const": "per_sample"}}}}},
    "then": {"properties": {"grid": {"not": {"required": ["seed"]}},
                            "monte_carlo": {"properties": {"fields": {"not": {"required": ["seed"]}}}}}},
}


def _component(spec: dict[str, Any], schema: dict[str, Any]) -> dict[str, Any] | None:
    ref = schema.get("$ref")
    if isinstance(ref, str) and ref.startswith(REF):
        found: dict[str, Any] | None = spec["components"]["schemas"].get(ref[len(REF):])
        return found
    return None


def _members(spec: dict[str, Any], schema: dict[str, Any]) -> list[dict[str, Any]]:
    """The object schemas a field's value may be: its component, or each object member of a union."""
    own = _component(spec, schema)
    if own is not None:
        return [own] if "properties" in own else []
    out = []
    for option in schema.get("oneOf", []) + schema.get("anyOf", []):
        member = _component(spec, option)
        if member is not None and "properties" in member:
            out.append(member)
    return out


def scenario_paths(spec: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Every field path of the ``Scenario`` schema in ``spec`` -> the schema of its value (copied)."""
    out: dict[str, dict[str, Any]] = {}

    def walk(properties: dict[str, Any], prefix: str) -> None:
        for name, schema in properties.items():
            path = f"{prefix}{name}"
            value = {k: v for k, v in schema.items() if k not in ("title", "default", "description")}
            out[path] = {"anyOf": [out[path], value]} if path in out and out[path] != value else value
            for member in _members(spec, schema):
                walk(member["properties"], f"{path}.")

    walk(spec["components"]["schemas"]["Scenario"]["properties"], "")
    return copy.deepcopy(out)


def tighten_study(spec: dict[str, Any], study: dict[str, Any]) -> None:
    """Write the grid's paths and values and the base's schema into the ``StudySpec`` schema ``study``."""
    props = study["properties"]
    if "grid" in props:
        grid = props["grid"]
        grid["properties"] = {path: {"type": "array", "minItems": 1, "items": value}
                              for path, value in scenario_paths(spec).items()}
        grid["additionalProperties"] = False
        paths = list(grid["properties"])
        nested = [[a, b] for a in paths for b in paths if b.startswith(a + ".")]
        grid["not"] = {"anyOf": [{"required": pair} for pair in nested]}  # never a field and one inside it
    study.setdefault("allOf", []).append(SEED_VARIED_ONCE)
    if "base" in props:
        props["base"] = {"$ref": REF + "Scenario", "description": props["base"].get("description", "")}
