"""The 3D view's gate: Host and Origin checks on viser's own HTTP/websocket server, and who may act.

viser serves its page and its websocket on its own port with no hook for either check, and a web
page anywhere may open a websocket to 127.0.0.1 (browsers do not apply the same-origin policy to
websockets): before, such a page set the duration and pressed "Start run".  Here:

* :func:`guarded_viser_server` builds the ``viser.ViserServer`` with a ``process_request`` check in
  front of viser's own: the Host must be loopback (or ``Settings.allowed_hosts``), and a websocket
  handshake's Origin must be the view's own (``http://`` + its Host) or one of
  ``Settings.allowed_origins``; else 421 / 403 before the connection exists.
* :class:`ClientAccess` decides which connected client may act: everyone without an API token; with
  one, only a client that typed it into its own (per-client) "API token" field; the others see the
  scene read-only.  Every callback checks it on the server (a client can flip any GUI property,
  ``disabled`` included, so nothing in the browser is a check).
"""

from __future__ import annotations

import contextlib
import http
import logging
import threading
from collections.abc import Iterable, Iterator
from typing import Any

import viser
import websockets.asyncio.server as ws_server

from backend.core.security import allowed_host, same_origin, token_ok

log = logging.getLogger(__name__)

_SERVE_LOCK = threading.Lock()  # the patch below is in force only while one view is being built


def handshake_problem(headers: Any, hosts: Iterable[str], origins: Iterable[str]) -> tuple[int, str] | None:
    """Why viser must not answer this request (status, text), or ``None``.

    >>> handshake_problem({"Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:8080", "Upgrade": "websocket"}, (), ())
    >>> handshake_problem({"Host": "127.0.0.1:8080", "Origin": "http://evil.example", "Upgrade": "websocket"}, (), ())
    (403, "cross-site websocket from 'http://evil.example' refused")
    >>> handshake_problem({"Host": "evil.example:8080"}, (), ())[0]
    421
    """
    host = headers.get("Host") or ""
    if not allowed_host(host, hosts):
        return 421, f"this 3D view does not answer to the Host {host!r}"
    origin = headers.get("Origin")
    websocket = (headers.get("Upgrade") or "").lower() == "websocket"
    if websocket and origin is not None and not (
            same_origin(origin, "http", host) or origin.lower().rstrip("/") in set(origins)):
        return 403, f"cross-site websocket from {origin!r} refused"
    return None


@contextlib.contextmanager
def _checked_serve(hosts: tuple[str, ...], origins: tuple[str, ...]) -> Iterator[None]:
    """While viser's server starts: its ``websockets`` serve() gets the handshake check in front."""
    original = ws_server.serve

    def serve(handler: Any, *args: Any, process_request: Any = None, **kwargs: Any) -> Any:
        def check(connection: Any, request: Any) -> Any:
            problem = handshake_problem(request.headers, hosts, origins)
            if problem is not None:
                log.warning("3D view refused %s: %s", request.path, problem[1])
                return connection.respond(http.HTTPStatus(problem[0]), problem[1] + "\n")
            return process_request(connection, request) if process_request is not None else None

        return original(handler, *args, process_request=check, **kwargs)

    with _SERVE_LOCK:
        ws_server.serve = serve  # type: ignore[assignment,misc]
        try:
            yield
        finally:
            ws_server.serve = original  # type: ignore[assignment,misc]


def guarded_viser_server(host: str, port: int, *, allowed_hosts: Iterable[str] = (),
                         allowed_origins: Iterable[str] = ()) -> viser.ViserServer:
    """``viser.ViserServer(host, port)`` whose HTTP and websocket handshakes pass :func:`handshake_problem`."""
    origins = tuple(o.strip().lower().rstrip("/") for o in allowed_origins)
    with _checked_serve((*allowed_hosts, host), origins):
        return viser.ViserServer(host=host, port=port, label="furnace-twin", verbose=False)


class ClientAccess:
    """Which viser clients may start, change and stop runs (module docstring)."""

    def __init__(self, token: str | None) -> None:
        self.token = token
        self._allowed: set[int] = set()
        self._lock = threading.Lock()
        self.fields: dict[int, Any] = {}  # each client's token field
    @property
    def open(self) -> bool:
        return not self.token

    def may_act(self, client_id: int) -> bool:
        if not self.token:
            return True
        with self._lock:
            return client_id in self._allowed

    def offer(self, client_id: int, given: str) -> bool:
        """A client typed ``given`` into its token field; True if it may act now."""
        ok = bool(self.token) and token_ok(given.strip(), self.token or "")
        with self._lock:
            (self._allowed.add if ok else self._allowed.discard)(client_id)
        return ok or not self.token

    def forget(self, client_id: int) -> None:
        with self._lock:
            self._allowed.discard(client_id)

    def attach(self, server: viser.ViserServer) -> None:
        """With a token: each client gets its own "API token" field (and forgets its access on leaving)."""
        if not self.token:
            return

        @server.on_client_connect
        def _(client: Any) -> None:
            with client.gui.add_folder("Access"):
                note = client.gui.add_markdown("read-only: enter this server's API token to start, change or "
                                               "stop runs")
                field = client.gui.add_text("API token", "")
            self.fields[client.client_id] = field

            @field.on_update
            def _(_: Any) -> None:
                if self.offer(client.client_id, field.value):
                    note.content = "controls enabled for this window"
                else:
                    note.content = "**wrong token**: read-only"

        @server.on_client_disconnect
        def _(client: Any) -> None:
            self.forget(client.client_id)
            self.fields.pop(client.client_id, None)
