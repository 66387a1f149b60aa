"""Refusals in plain words: pydantic's validation errors as sentences an engineer reads without the
library's vocabulary ("Input should be 'max'", "literal_error", "union_tag_invalid", ...).

:func:`plain_errors` turns the error list of a ``RequestValidationError`` / ``ValidationError``
into the same list shape (``loc``, ``msg``, ``type``), with ``loc`` free of pydantic's internal
steps (union members such as ``literal['max']`` or ``float``, the reference's ``transition`` tag)
and one error per field: the alternatives of a union (``speed``: 'max' or a number) become one
sentence.  The 422 handler of ``backend.app`` answers with it; ``RunChecks`` uses it for the
one-line messages of live changes.

Example
-------
>>> errs = [{"type": "literal_error", "loc": ("body", "speed", "literal['max']"), "msg": "Input should be 'max'",
...          "input": "fast", "ctx": {"expected": "'max'"}},
...         {"type": "float_parsing", "loc": ("body", "speed", "float"), "msg": "Input should be a valid number",
...          "input": "fast"}]
>>> [(e["loc"], e["msg"]) for e in plain_errors(errs)]
[(['body', 'speed'], "'fast' is neither 'max' nor a number: 'max' or a real-time factor")]
>>> field_path(("body", "reference", "points", 1, 0))
'reference › point 2 › time'
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

#: what a field may hold, said in words (where the type alone does not say it)
FIELD_WORDS = {
    "speed": "'max' or a real-time factor",
    "reference": "either {\"setpoint\", \"t_E\"} or {\"points\": [[t, T], ...]}",
    "tc4": "two numbers, x / L_s and y / W_s",
    "points": "a list of [time in s, temperature in K] pairs",
}
_TYPE_NAMES = {"float", "int", "str", "bool", "list", "dict", "tuple", "none", "transition"}


def _is_internal(step: Any) -> bool:
    """A loc step that names a union member or a tag, not a field (``literal['max']``, ``float``, ...)."""
    return isinstance(step, str) and ("[" in step or step in _TYPE_NAMES or step.startswith("function-"))


def clean_loc(loc: Sequence[Any]) -> list[Any]:
    """``loc`` without pydantic's internal steps (union members, and a tag that repeats its field's name:
    ``reference › points › points`` is ``reference › points``)."""
    out: list[Any] = []
    for p in loc:
        if not _is_internal(p) and not (out and isinstance(p, str) and out[-1] == p):
            out.append(p)
    return out


def _num(x: Any) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _entries(n: Any) -> str:
    return f"{n} entry" if n == 1 else f"{n} entries"


def field_path(loc: Sequence[Any]) -> str:
    """A location as words: ``reference › point 2 › temperature`` (no ``body``, no union members)."""
    parts: list[str] = []
    steps = [p for p in clean_loc(loc) if p != "body"]
    k = 0
    while k < len(steps):
        p = steps[k]
        if isinstance(p, int) and parts and parts[-1] == "points":
            parts[-1] = f"point {p + 1}"
            if k + 1 < len(steps) and steps[k + 1] in (0, 1):
                parts.append("time" if steps[k + 1] == 0 else "temperature")
                k += 1
        elif isinstance(p, int) and parts and parts[-1] == "tc4":
            parts[-1] = f"tc4 {'x' if p == 0 else 'y'}"
        else:
            parts.append(str(p))
        k += 1
    return " › ".join(parts) if parts else "body"


SHOWN_CHARS = 40  # a value quoted in a message is cut to this many characters (a message never echoes a big input)


def _shown(value: Any) -> str:
    if isinstance(value, str):
        if len(value) > SHOWN_CHARS:
            return f"'{value[:SHOWN_CHARS]}…' ({len(value)} characters)"
        return f"'{value}'" if value else "an empty text"
    if isinstance(value, float) and value != value:
        return "NaN"
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list | tuple):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "an object"
    return str(value)[:SHOWN_CHARS]


def plain_message(e: Mapping[str, Any]) -> str:
    """One error's message in plain words (without its location)."""
    kind = str(e.get("type", ""))
    ctx = e.get("ctx") or {}
    got = e.get("input")
    loc = clean_loc(e.get("loc", ()))
    words = FIELD_WORDS.get(loc[-1]) if loc and isinstance(loc[-1], str) else None  # the field itself
    if kind == "missing":
        return "is missing" + (f": {words}" if words else "")
    if kind == "extra_forbidden":
        return "is not a field here (a typo?)"
    if kind in ("float_type", "float_parsing", "int_type", "int_parsing", "int_from_float", "finite_number"):
        what = "a whole number" if kind.startswith("int") else "a finite number" if kind == "finite_number" \
            else "a number"
        return f"must be {what}, got {_shown(got)}" + (f" ({words})" if words else "")
    if kind in ("bool_type", "bool_parsing"):
        return f"must be true or false, got {_shown(got)}"
    if kind == "literal_error":
        return f"must be {ctx.get('expected', 'one of the listed values')}, got {_shown(got)}"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        bound = {"greater_than": ("above", "gt"), "greater_than_equal": ("at least", "ge"),
                 "less_than": ("below", "lt"), "less_than_equal": ("at most", "le")}[kind]
        return f"must be {bound[0]} {_num(ctx.get(bound[1]))}, got {_shown(got)}"
    if kind == "too_short":
        return f"needs at least {_entries(ctx.get('min_length'))}, got {ctx.get('actual_length')}"
    if kind == "too_long":
        return f"takes at most {_entries(ctx.get('max_length'))}, got {ctx.get('actual_length')}"
    if kind in ("list_type", "tuple_type"):
        return f"must be a list, got {_shown(got)}" + (f": {words}" if words else "")
    if kind in ("model_type", "model_attributes_type", "dict_type"):
        return f"must be an object, got {_shown(got)}" + (f": {words}" if words else "")
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        return f"must be {words or 'one of the allowed forms'}"
    if kind in ("json_invalid", "json_type"):
        return "the body is not valid JSON"
    if kind in ("string_type", "string_too_long"):
        return f"must be a text, got {_shown(got)}"
    msg = str(e.get("msg", "invalid"))
    return msg.removeprefix("Value error, ").removeprefix("Assertion failed, ")


def _union_message(group: list[Mapping[str, Any]], name: str) -> str:
    """The errors of one field's union alternatives as one sentence."""
    got = group[0].get("input")
    options = []
    for e in group:
        kind = str(e.get("type", ""))
        if kind == "literal_error":
            options.append(str((e.get("ctx") or {}).get("expected", "")))
        elif kind.startswith(("float", "int")):
            options.append("a number")
        else:
            return "; ".join(dict.fromkeys(plain_message(x) for x in group))
    words = FIELD_WORDS.get(name)
    return f"{_shown(got)} is neither {' nor '.join(options)}" + (f": {words}" if words else "")


def plain_errors(errors: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Validation errors as ``[{loc, msg, type, input}]`` with plain messages, one per field location."""
    groups: dict[tuple[Any, ...], list[Mapping[str, Any]]] = {}
    for e in errors:
        groups.setdefault(tuple(clean_loc(e.get("loc", ()))), []).append(e)
    out = []
    for loc, group in groups.items():
        name = next((str(p) for p in reversed(loc) if isinstance(p, str)), "")
        internal = [any(_is_internal(p) for p in e.get("loc", ())) for e in group]
        if len(group) > 1 and all(internal):
            msg = _union_message(group, name)
        else:
            msg = "; ".join(dict.fromkeys(plain_message(e) for e in group))
        one: dict[str, Any] = {"loc": list(loc), "msg": msg, "type": str(group[0].get("type", ""))}
        if "input" in group[0]:
            one["input"] = group[0]["input"]  # as given (the 422 handler shortens it)
        out.append(one)
    return out
