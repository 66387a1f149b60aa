"""The JSON files a user names on the command line: a scenario (``furnace-twin run --scenario``,
``furnace-twin emulate --scenario``), read with messages that name the file and the field.

A file that cannot be read, is not JSON, is not an object, or holds a field outside the furnace's limits
raises :class:`ScenarioError` (a ``ValueError``) with one plain message; the commands print it and exit 2.

Example
-------
>>> load_scenario(None, oscillate=True).oscillation.enabled
True
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from twin.limits import ScenarioLimits
from twin.scenario import Scenario, parse_scenario


class ScenarioError(ValueError):
    """A scenario file or option is invalid; the message says which field and why."""


def read_json(path: str, what: str, error: type[ValueError]) -> Any:
    """The JSON value in the file at ``path``; ``error`` with one sentence naming ``what`` and the file if it
    cannot be read or is not JSON."""
    try:
        return json.loads(Path(path).read_text())
    except OSError as exc:
        raise error(f"cannot read {what} {path}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise error(f"{what} {path} is not valid JSON: {exc}") from None


def load_scenario(
    path: str | None,
    limits: ScenarioLimits | None = None,
    *,
    oscillate: bool = False,
    tc4: tuple[float, float] | None = None,
) -> Scenario:
    """Read a scenario JSON file (or the defaults) and apply command-line overrides; the scenario is
    checked against the furnace's ``limits`` (``twin.limits``; default: the default furnace's) and
    fields the file leaves out take that furnace's defaults."""
    data: dict[str, Any] = {}
    if path is not None:
        data = read_json(path, "scenario", ScenarioError)
        if not isinstance(data, dict):
            raise ScenarioError(f"scenario {path} must be a JSON object")
    if oscillate:
        data["oscillation"] = {**data.get("oscillation", {}), "enabled": True}
    if tc4 is not None:
        data["tc4"] = list(tc4)
    try:
        return parse_scenario(data, limits)
    except ValidationError as exc:
        msgs = [f"{'.'.join(str(p) for p in e['loc'])}: {e['msg'].removeprefix('Value error, ')}"
                for e in exc.errors()]
        raise ScenarioError("invalid scenario:\n  " + "\n  ".join(msgs)) from None
