"""The HTTP answers that FastAPI gives on its own, made to say what the OpenAPI schema says.

Two gaps that schemathesis (``st run URL/openapi.json --checks all``) found:

- **405 and ``Allow``.**  FastAPI makes one route per method, so ``DELETE`` and ``GET`` on the same path are
  two routes; a method neither takes gets the 405 of the *first* one, whose ``Allow`` names only its own
  method (``OPTIONS /api/furnace/calibration`` answered ``Allow: GET`` though ``DELETE`` is served too).
  :func:`http_error` lists every method the schema documents for the path (RFC 9110, 15.5.6).
- **400 for a body that is not text.**  A body that is not UTF-8 (or not JSON at all, for FastAPI's decoder)
  is answered ``400 There was an error parsing the body`` by FastAPI itself, a status no operation
  documented.  :func:`document_body_errors` documents it on every operation that takes a body.
"""

from __future__ import annotations

import re
from typing import Any

from fastapi import Request
from fastapi.exception_handlers import http_exception_handler
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response

HTTP_METHODS = frozenset({"GET", "PUT", "POST", "DELETE", "OPTIONS", "HEAD", "PATCH", "TRACE"})
BODY_ERROR: dict[str, Any] = {
    "description": "the body could not be read: not UTF-8 text or not JSON (send a JSON document)",
}


def allowed_methods(spec: dict[str, Any], path: str) -> list[str]:
    """The methods the OpenAPI ``spec`` documents for the request path ``path`` (FastAPI serves no HEAD of its
    own); empty for a path the schema does not hold (the dashboard's pages, say)."""
    for template, item in spec.get("paths", {}).items():
        pattern = "^" + re.sub(r"\\\{[^/]+?\\\}", "[^/]+", re.escape(template)) + "$"
        if re.match(pattern, path):
            methods = {m.upper() for m in item if m.upper() in HTTP_METHODS}
            return sorted(methods)
    return []


async def http_error(request: Request, exc: Exception) -> Response:
    """FastAPI's answer to an HTTP error, with a 405's ``Allow`` naming every method of the path."""
    assert isinstance(exc, StarletteHTTPException)
    if exc.status_code == 405:
        methods = allowed_methods(request.app.openapi(), request.url.path)
        if methods:
            exc = StarletteHTTPException(405, exc.detail, headers={**(exc.headers or {}), "Allow": ", ".join(methods)})
    return await http_exception_handler(request, exc)


def document_body_errors(spec: dict[str, Any]) -> dict[str, Any]:
    """Add the 400 of an unreadable body to every operation of ``spec`` that takes a body; returns ``spec``."""
    for item in spec.get("paths", {}).values():
        for method, operation in item.items():
            if method.upper() in HTTP_METHODS and "requestBody" in operation:
                operation.setdefault("responses", {}).setdefault("400", dict(BODY_ERROR))
    return spec
