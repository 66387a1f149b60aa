"""The server's gate: what a request must be before any route sees it (pure ASGI middleware).

Checked in this order, for HTTP requests and websocket handshakes alike, before a body is read,
parsed or a token compared:

1. **Host** (DNS rebinding): only loopback names and addresses (``localhost``, 127.0.0.0/8, ``::1``),
   the address the server listens on, and ``Settings.allowed_hosts``; else 421.
2. **Origin** (cross-site requests): a request that changes something (POST, PUT, PATCH, DELETE) and
   every websocket handshake must come without an ``Origin`` (curl, scripts) or from the server's own
   origin (``scheme://`` + its Host header: the dashboard) or one of ``Settings.allowed_origins``; else 403.
   A web page elsewhere can send a request to 127.0.0.1, but not with its Origin taken away.
3. **Content type**: a mutating request with a body must say ``application/json``; else 415.  A
   ``text/plain`` or form body is what a cross-site page can send without a CORS preflight.
4. **Body size**: a body over ``Settings.max_body_bytes`` is a 413, judged from its Content-Length,
   or, for a chunked body, after reading at most that many bytes (nothing more is buffered).
5. **Token**: with ``Settings.api_token`` set, mutating requests need it, and, when the server
   listens beyond loopback (``Settings.reads_need_token``), every ``/api`` request except
   ``/api/health`` and every websocket (its subprotocol ``token.<token>``, since browsers cannot set
   headers on a websocket); else 401.  The routes check the token of a mutation again (``backend.api.deps``).

Example
-------
>>> allowed_host("127.0.0.1:8000", ()), allowed_host("localhost", ()), allowed_host("evil.example:8000", ())
(True, True, False)
>>> allowed_host("[::1]:8000", ()), allowed_host("furnace.lab:8000", ("furnace.lab",))
(True, True)
>>> same_origin("http://127.0.0.1:8000", "http", "127.0.0.1:8000")
True
>>> same_origin("http://evil.example", "http", "127.0.0.1:8000")
False
"""

from __future__ import annotations

import json
import logging
import secrets
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from typing import Any

from backend.core.settings import Settings, is_loopback

log = logging.getLogger(__name__)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

MUTATING = frozenset({"POST", "PUT", "PATCH", "DELETE"})
TOKEN_SUBPROTOCOL = "token."  # websocket: Sec-WebSocket-Protocol "token.<token>"
STREAM_SUBPROTOCOL = "furnace-twin"  # what the server answers when a client offered a token subprotocol
PUBLIC_PATHS = frozenset({"/api/health"})


def split_host(host: str) -> str:
    """The name of a Host header without its port (``[::1]:80`` -> ``::1``)."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def allowed_host(host: str, extra: Iterable[str]) -> bool:
    """Whether a Host header names this server: loopback, or one of ``extra`` (names or addresses)."""
    name = split_host(host)
    if not name:
        return False
    return is_loopback(name) or name in {split_host(h) for h in extra}


def same_origin(origin: str, scheme: str, host: str) -> bool:
    """Whether ``origin`` is the server's own origin as the client reached it (``scheme://host``)."""
    want = "https" if scheme in ("https", "wss") else "http"
    return origin.strip().lower().rstrip("/") == f"{want}://{host.strip().lower()}"


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}


def given_token(headers: dict[str, str]) -> str | None:
    """The token a request carries: ``X-API-Token``, ``Authorization: Bearer``, or a ``token.`` subprotocol."""
    if "x-api-token" in headers:
        return headers["x-api-token"].strip()
    auth = headers.get("authorization", "")
    if auth.lower().startswith("bearer "):
        return auth[7:].strip()
    for proto in headers.get("sec-websocket-protocol", "").split(","):
        proto = proto.strip()
        if proto.startswith(TOKEN_SUBPROTOCOL):
            return proto[len(TOKEN_SUBPROTOCOL):]
    return None


def token_ok(given: str | None, expected: str) -> bool:
    return given is not None and secrets.compare_digest(given.encode(), expected.encode())


class SecurityMiddleware:
    """The checks of the module docstring, in front of the whole app."""

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        self.settings = settings
        hosts = list(settings.allowed_hosts)
        if settings.host not in ("0.0.0.0", "::", ""):
            hosts.append(settings.host)  # the address it was told to listen on
        self.hosts = tuple(hosts)
        self.origins = frozenset(o.strip().lower().rstrip("/") for o in settings.allowed_origins)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        headers = _headers(scope)
        refusal = self._refusal(scope, headers)
        if refusal is None and scope["type"] == "http" and scope.get("method") in MUTATING:
            bounded = await self._bounded_body(scope, receive, send, headers)
            if bounded is None:
                return None  # 413 sent
            receive = bounded
        if refusal is None:
            refusal = self._unauthorized(scope, headers)
        if refusal is not None:
            code, message = refusal
            log.warning("refused %s %s: %d %s", scope.get("method", "WS"), scope.get("path"), code, message)
            return await _refuse(scope, receive, send, code, message)
        return await self.app(scope, receive, send)

    def _refusal(self, scope: Scope, headers: dict[str, str]) -> tuple[int, str] | None:
        s = self.settings
        host = headers.get("host", "")
        if not allowed_host(host, self.hosts):
            return 421, (f"this server does not answer to the Host {host!r}: it answers to loopback names "
                         f"(or FURNACE_TWIN_ALLOWED_HOSTS)")
        websocket = scope["type"] == "websocket"
        mutating = websocket or scope.get("method") in MUTATING
        origin = headers.get("origin")
        if mutating and origin is not None and not (
                same_origin(origin, scope.get("scheme", "http"), host) or origin.lower().rstrip("/") in self.origins):
            return 403, f"cross-site request from {origin!r} refused (allowed: this server's own pages)"
        if not websocket and mutating:
            length = headers.get("content-length")
            has_body = "transfer-encoding" in headers or (length is not None and length.strip() not in ("", "0"))
            ctype = headers.get("content-type", "").split(";")[0].strip().lower()
            if has_body and ctype != "application/json":
                return 415, f"send the body as JSON (Content-Type: application/json), not {ctype or 'untyped'}"
            if length is not None:
                try:
                    n = int(length)
                except ValueError:
                    return 400, "Content-Length is not a number"
                if n > s.max_body_bytes:
                    return 413, f"the body has {n} bytes; this server accepts at most {s.max_body_bytes}"
        return None

    def _unauthorized(self, scope: Scope, headers: dict[str, str]) -> tuple[int, str] | None:
        s = self.settings
        websocket = scope["type"] == "websocket"
        mutating = websocket or scope.get("method") in MUTATING
        if s.api_token:
            path = scope.get("path", "")
            needs = (mutating and not websocket) or (
                s.reads_need_token and (websocket or path.startswith("/api")) and path not in PUBLIC_PATHS)
            if needs and not token_ok(given_token(headers), s.api_token):
                return 401, ("this server needs its API token: send 'Authorization: Bearer <token>' or "
                             "'X-API-Token' (websocket: subprotocol 'token.<token>')")
        return None

    async def _bounded_body(self, scope: Scope, receive: Receive, send: Send,
                            headers: dict[str, str]) -> Receive | None:
        """A chunked body is read here up to the limit (a body with a Content-Length was judged by it)."""
        if "content-length" in headers or "transfer-encoding" not in headers:
            return receive
        limit = self.settings.max_body_bytes
        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                return receive  # the client went away; let the app see it
            size += len(message.get("body", b""))
            if size > limit:
                await _refuse(scope, receive, send, 413, f"the body has more than {limit} bytes; this server accepts "
                                                f"at most {limit}")
                return None
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        sent = False

        async def replay() -> Message:
            nonlocal sent
            if not sent:
                sent = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        return replay


async def _refuse(scope: Scope, receive: Receive, send: Send, code: int, message: str) -> None:
    """A JSON ``{"detail": ...}`` answer (a websocket: the denial response, or a close before accept)."""
    body = json.dumps({"detail": message}).encode()
    head = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    if code == 401:
        head.append((b"www-authenticate", b"Bearer"))
    if scope["type"] == "http":
        await send({"type": "http.response.start", "status": code, "headers": head})
        await send({"type": "http.response.body", "body": body})
        return
    await receive()  # websocket.connect
    if "websocket.http.response" in scope.get("extensions", {}):
        await send({"type": "websocket.http.response.start", "status": code, "headers": head})
        await send({"type": "websocket.http.response.body", "body": body})
    else:
        await send({"type": "websocket.close", "code": 4000 + code, "reason": message[:120]})


__all__ = ["STREAM_SUBPROTOCOL", "TOKEN_SUBPROTOCOL", "SecurityMiddleware", "allowed_host", "given_token",
           "same_origin", "token_ok"]
