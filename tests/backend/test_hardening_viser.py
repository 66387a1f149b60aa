"""Issue 15, finding 4: the 3D view bypassed the token and accepted any Origin.

Before: with FURNACE_TWIN_API_TOKEN set, a websocket client with ``Origin: http://evil.example`` set the
duration and pressed "Start run", and a run started.  Here a raw websocket client speaks viser's own
protocol (msgpack GuiUpdateMessage) to the real viser server of the app.
"""

from __future__ import annotations

import time

import httpx
import msgspec
import pytest
import viser
from fastapi.testclient import TestClient
from viser._messages import GuiUpdateMessage, ViewerCameraMessage
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import free_port
from conftest import fake_factory

TOKEN = "view-token-0123456789"
PROTOCOL = f"viser-v{viser.__version__}"


def send(ws, uuid: str, value) -> None:
    ws.send(msgspec.msgpack.encode(GuiUpdateMessage(uuid, {"value": value}).as_serializable_dict()))


def hello(ws) -> None:
    """What a browser sends first: viser counts a client as connected from its first camera message."""
    cam = ViewerCameraMessage(wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, 0.0, -1.0), fov=1.0, near=0.01, far=100.0,
                              image_height=480, image_width=640, look_at=(0.0, 0.0, 0.0), up_direction=(0.0, 0.0, 1.0))
    ws.send(msgspec.msgpack.encode(cam.as_serializable_dict()))


def wait_for(predicate, timeout: float = 20.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.05)
    return predicate()


@pytest.fixture
def view_app(tmp_path, small_cfg):
    s = Settings(data_dir=tmp_path / "data", viser_port=free_port(), api_token=TOKEN)
    app = create_app(s, small_cfg, loop_factory=fake_factory(), viser=True)
    with TestClient(app, base_url="http://127.0.0.1") as c:
        yield app, c


def test_finding_04_view_refuses_foreign_origin_and_host(view_app) -> None:
    app, _ = view_app
    port = app.state.viser.port
    with pytest.raises(InvalidStatus) as exc:
        connect(f"ws://127.0.0.1:{port}", origin="http://evil.example", subprotocols=[PROTOCOL], open_timeout=10)
    assert exc.value.response.status_code == 403
    assert httpx.get(f"http://127.0.0.1:{port}/", headers={"Host": "evil.example"}, timeout=10).status_code == 421
    assert httpx.get(f"http://127.0.0.1:{port}/", timeout=10).status_code == 200  # the page itself
    with connect(f"ws://127.0.0.1:{port}", origin=f"http://127.0.0.1:{port}", subprotocols=[PROTOCOL],
                 open_timeout=10) as ws:
        assert ws.recv(timeout=10)  # the scene arrives


def test_finding_04_controls_need_the_token(view_app) -> None:
    app, c = view_app
    view = app.state.viser
    port = view.port
    with connect(f"ws://127.0.0.1:{port}", origin=f"http://127.0.0.1:{port}", subprotocols=[PROTOCOL],
                 open_timeout=10) as ws:
        hello(ws)
        assert wait_for(lambda: len(view.access.fields) == 1)
        (client_id, field), = view.access.fields.items()
        send(ws, view.gui.duration._impl.uuid, 5.0)
        send(ws, view.gui.start._impl.uuid, True)
        assert wait_for(lambda: "read-only" in view.gui.message.content)
        assert c.get("/api/runs").json() == []  # nothing started
        send(ws, field._impl.uuid, "wrong-token-0123456")
        send(ws, view.gui.start._impl.uuid, True)
        time.sleep(0.5)
        assert c.get("/api/runs").json() == []
        send(ws, field._impl.uuid, TOKEN)
        assert wait_for(lambda: view.access.may_act(client_id))
        send(ws, view.gui.start._impl.uuid, True)
        assert wait_for(lambda: len(c.get("/api/runs").json()) == 1)
        assert c.get("/api/runs").json()[0]["scenario"]["duration"] == 5.0


def test_finding_04_control_ranges_are_checked_on_the_server(tmp_path, small_cfg) -> None:
    """A client can send any value (and flip min, max or disabled): the start is checked against twin.limits."""
    s = Settings(data_dir=tmp_path / "data", viser_port=free_port())
    app = create_app(s, small_cfg, loop_factory=fake_factory(), viser=True)
    with TestClient(app, base_url="http://127.0.0.1") as c:
        view = app.state.viser
        port = view.port
        with connect(f"ws://127.0.0.1:{port}", origin=f"http://127.0.0.1:{port}", subprotocols=[PROTOCOL],
                     open_timeout=10) as ws:
            hello(ws)
            for handle, value in ((view.gui.duration, 1e9), (view.gui.t_E, 1e9)):
                send(ws, handle._impl.uuid, value)
            assert wait_for(lambda: view.gui.duration.value == 1e9)  # viser itself takes any number
            send(ws, view.gui.start._impl.uuid, True)
            assert wait_for(lambda: "refused" in view.gui.message.content)
            assert "duration" in view.gui.message.content
            assert c.get("/api/runs").json() == []
