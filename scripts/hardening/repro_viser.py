"""Finding 4 evidence: a websocket client with a foreign Origin drives the 3D view of a server with a token."""
import sys, time, tempfile
from pathlib import Path
sys.path.insert(0, "tests/backend")
import msgspec, viser
from conftest import fake_factory
from fastapi.testclient import TestClient
from viser._messages import GuiUpdateMessage, ViewerCameraMessage
from websockets.sync.client import connect
from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import free_port
from twin.config import small_config
def enc(m): return msgspec.msgpack.encode(m.as_serializable_dict())
s = Settings(data_dir=Path(tempfile.mkdtemp()), viser_port=free_port(), api_token="view-token-0123456789")
app = create_app(s, small_config(), loop_factory=fake_factory(), viser=True)
with TestClient(app, base_url="http://127.0.0.1") as c:
    v = app.state.viser
    try:
        ws = connect(f"ws://127.0.0.1:{v.port}", origin="http://evil.example", subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10)
    except Exception as e:
        print("finding 4: Origin http://evil.example ->", type(e).__name__, getattr(getattr(e, "response", None), "status_code", ""))
        sys.exit(0)
    print("finding 4: Origin http://evil.example -> connected")
    ws.send(enc(ViewerCameraMessage((1.0, 0, 0, 0), (0, 0, -1.0), 1.0, 0.01, 100.0, 480, 640, (0, 0, 0), (0, 0, 1.0))))
    time.sleep(0.5)
    ws.send(enc(GuiUpdateMessage(v.gui.duration._impl.uuid, {"value": 5.0})))
    ws.send(enc(GuiUpdateMessage(v.gui.start._impl.uuid, {"value": True})))
    time.sleep(3)
    print("finding 4: runs started by it (no token sent):", len(c.get("/api/runs").json()))
    ws.close()
