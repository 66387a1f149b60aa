"""``WS /api/runs/{id}/stream``: the run's frames (backend.streaming.frames), one bounded queue per client."""

from __future__ import annotations

import asyncio
import contextlib
import logging

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from fastapi.responses import PlainTextResponse

from backend.core.security import STREAM_SUBPROTOCOL, TOKEN_SUBPROTOCOL
from backend.runs.manager import RunManager, RunNotFound

log = logging.getLogger(__name__)
router = APIRouter(prefix="/api/runs", tags=["stream"])


async def _deny(ws: WebSocket, code: int, message: str) -> None:
    try:
        await ws.send_denial_response(PlainTextResponse(message, status_code=code))
    except RuntimeError:  # server without the denial-response extension
        await ws.close(code=4000 + code, reason=message)


@router.websocket("/{run_id}/stream")
async def stream(ws: WebSocket, run_id: str) -> None:
    """Frames of a running run until it ends; an ended run sends its last frame and closes."""
    manager: RunManager = ws.app.state.manager
    try:
        manager.run(run_id)
    except RunNotFound as exc:
        await _deny(ws, 404, str(exc))
        return
    hub = manager.hub(run_id)
    # subscribed before the handshake completes: a page that reads the run's history once the stream is open
    # gets every frame after it (none falls between the history and the first frame)
    sub = hub.subscribe() if hub is not None else None
    # a browser sends its token as a subprotocol (backend.core.security); answer with ours, never the token
    offered = ws.scope.get("subprotocols") or []
    try:
        await ws.accept(subprotocol=STREAM_SUBPROTOCOL if STREAM_SUBPROTOCOL in offered or any(
            p.startswith(TOKEN_SUBPROTOCOL) for p in offered) else None)
    except BaseException:
        if hub is not None and sub is not None:
            hub.unsubscribe(sub)
        raise
    if hub is None or sub is None:
        last = manager.last_frame(run_id)
        if last is not None:
            await ws.send_text(last)
        await ws.close(code=1000, reason="the run has ended")
        return
    send_timeout = ws.app.state.settings.client_send_timeout_s

    async def watch_disconnect() -> None:
        with contextlib.suppress(WebSocketDisconnect, RuntimeError):
            while True:
                msg = await ws.receive()
                if msg["type"] == "websocket.disconnect":
                    return

    watcher = asyncio.create_task(watch_disconnect())
    try:
        while True:
            getter = asyncio.ensure_future(sub.queue.get())
            done, _ = await asyncio.wait({getter, watcher}, return_when=asyncio.FIRST_COMPLETED)
            if getter not in done:
                getter.cancel()
                return  # client went away
            frame = getter.result()
            if frame is None:
                await ws.close(code=1000, reason="the run has ended")
                return
            try:
                await asyncio.wait_for(ws.send_text(frame), timeout=send_timeout)
            except TimeoutError:
                log.warning("run %s: a stream client took no frame for %.0f s; dropping it", run_id, send_timeout)
                return
            sub.delivered += 1
    except (WebSocketDisconnect, RuntimeError, ConnectionError):
        return
    finally:
        hub.unsubscribe(sub)
        watcher.cancel()
