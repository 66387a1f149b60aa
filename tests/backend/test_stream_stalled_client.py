"""A stalled websocket client (its ``send`` never returns) loses frames of its own and neither
slows the run nor the other clients.  The stalled client is a raw ASGI connection started on
the app's own event loop (TestClient.portal); the healthy one is a normal TestClient websocket."""

from __future__ import annotations

import asyncio
import json
import time

from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import fake_factory


async def stalled_client(app, path: str, accepted: list[bool]) -> None:
    connected = False

    async def receive() -> dict:
        nonlocal connected
        if not connected:
            connected = True
            return {"type": "websocket.connect"}
        await asyncio.Event().wait()  # the client never says anything more
        return {"type": "websocket.disconnect", "code": 1000}

    async def send(message: dict) -> None:
        if message["type"] == "websocket.accept":
            accepted.append(True)
            return
        await asyncio.Event().wait()  # a frame was handed over: this client never takes it

    scope = {"type": "websocket", "path": path, "raw_path": path.encode(), "query_string": b"",
             "headers": [(b"host", b"127.0.0.1")], "scheme": "ws", "server": ("127.0.0.1", 80),
             "client": ("stalled", 1),
             "root_path": "", "subprotocols": [], "asgi": {"version": "3.0"}, "state": {}}
    await app(scope, receive, send)


def test_stalled_client_does_not_slow_run_or_others(tmp_path, small_cfg) -> None:
    settings = Settings(data_dir=tmp_path / "data", client_send_timeout_s=1.0)
    app = create_app(settings, small_cfg, loop_factory=fake_factory())
    duration, speed = 6.0, 5.0
    with TestClient(app, base_url="http://127.0.0.1") as c:
        run_id = c.post("/api/runs", json={"duration": duration, "speed": speed}).json()["id"]
        accepted: list[bool] = []
        c.portal.start_task_soon(stalled_client, app, f"/api/runs/{run_id}/stream", accepted)
        frames = []
        with c.websocket_connect(f"ws://127.0.0.1/api/runs/{run_id}/stream") as ws:
            while True:
                try:
                    frames.append((time.time(), json.loads(ws.receive_text())))
                except Exception:
                    break
        assert accepted == [True]
        live = [f for _, f in frames if f["status"] == "running"]
        # the run kept its pace: 6 simulated s at speed 5 = 1.2 s of sample wall time
        wall = live[-1]["wall_time"] - live[0]["wall_time"]
        sim = live[-1]["t"] - live[0]["t"]
        # a blocked loop would wait for the stalled client's 10 s timeout; 0.5 s of slack tells the two
        # apart without flaking on a loaded 2-core machine
        assert abs(wall - sim / speed) < 0.5, (wall, sim)
        # the healthy client got the capped rate: 50 samples/s -> 20 frames/s over ~1.2 s
        assert (len(live) - 1) / wall > 10.0  # well above what a blocked loop would deliver (< 1/s)
        assert c.get(f"/api/runs/{run_id}").json()["status"] == "finished"
