"""Validation errors as JSON that is always valid and small.

FastAPI's own 422 echoes each offending input back; an input of NaN or Infinity (``1e999``) then
makes the JSON encoder fail (a 500 and a dropped connection), and a 100 MB input comes back as a
100 MB answer.  Here every echoed input is JSON-safe and at most :data:`MAX_ECHO_CHARS` long.

Example
-------
>>> echo(float("nan")), echo(1e999), echo([1.0] * 1000)
('NaN', 'Infinity', 'list of 1000 items')
>>> echo("x" * 500)[-13:]
'… (500 chars)'
"""

from __future__ import annotations

import json
import math
from typing import Any

from fastapi import Request, status
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from backend.core.messages import plain_errors

MAX_ECHO_CHARS = 200  # an echoed input longer than this is summarised
MAX_ERRORS = 20  # errors reported per request (a 1000-point list can make 2000)


def echo(value: Any) -> Any:
    """``value`` as JSON-safe and short: non-finite floats as their JSON-ish names, long things summarised."""
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    if isinstance(value, str):
        return value if len(value) <= MAX_ECHO_CHARS else f"{value[:MAX_ECHO_CHARS]}… ({len(value)} chars)"
    if value is None or isinstance(value, bool | int | float):
        return value
    if isinstance(value, list | tuple | dict):
        try:
            text = json.dumps(value, allow_nan=False)
        except (TypeError, ValueError):
            text = None
        if text is not None and len(text) <= MAX_ECHO_CHARS:
            return value
        kind = "object" if isinstance(value, dict) else "list"
        return f"{kind} of {len(value)} {'keys' if kind == 'object' else 'items'}"
    return echo(str(value))


def _error(e: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {"type": e.get("type"), "loc": list(e.get("loc", ())), "msg": str(e.get("msg", ""))}
    if "input" in e:
        out["input"] = echo(e["input"])
    return out


async def validation_error(request: Request, exc: Exception) -> JSONResponse:
    """422 with FastAPI's shape (``detail``: loc, msg, type, input) and never a non-finite or long echo; the
    messages in plain words, one per field (``backend.core.messages.plain_errors``: no pydantic wording)."""
    assert isinstance(exc, RequestValidationError)
    errors = plain_errors(exc.errors())
    detail = [_error(e) for e in errors[:MAX_ERRORS]]
    if len(errors) > MAX_ERRORS:
        detail.append({"type": "too_many_errors", "loc": ["body"],
                       "msg": f"and {len(errors) - MAX_ERRORS} more errors", "input": None})
    return JSONResponse({"detail": detail}, status_code=status.HTTP_422_UNPROCESSABLE_CONTENT)
