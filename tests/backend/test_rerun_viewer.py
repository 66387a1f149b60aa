"""The server's rerun web viewer (issue 14, part 1): rerun's own ``--serve-web`` child on loopback only
(``rr.serve_web_viewer`` would listen on 0.0.0.0: stack-notes.md), with its memory limits, stopped with the
server; runs link to it and their recording may be read from its origin."""

from __future__ import annotations

import time
import urllib.parse
from pathlib import Path

import httpx
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import free_port
from backend.streaming.rerun_viewer import RerunWebViewer, reachable
from conftest import fake_factory, wait_status


def _listening(port: int) -> set[str]:
    """Local addresses (hex, as in /proc/net/tcp*) listening on ``port``."""
    out = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not Path(table).exists():
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            addr, state = fields[1], fields[3]
            if state == "0A" and int(addr.rsplit(":", 1)[1], 16) == port:  # 0A = LISTEN
                out.add(addr.rsplit(":", 1)[0])
    return out


def test_viewer_on_loopback_with_memory_limits(tmp_path, isolated_home) -> None:
    viewer = RerunWebViewer(free_port(), free_port(), server_memory_limit="64MiB", memory_limit="256MiB",
                            log_dir=tmp_path)
    assert viewer.start(timeout_s=60)
    try:
        assert httpx.get(viewer.url, timeout=10).status_code == 200  # the viewer's page
        for port in (viewer.web_port, viewer.grpc_port):
            assert _listening(port) == {"0100007F"}, (port, _listening(port))  # 127.0.0.1 only
        cmd = " ".join(viewer.proc.args)
        assert "--server-memory-limit 64MiB" in cmd and "--memory-limit 256MiB" in cmd
        link = viewer.link("rerun+http://127.0.0.1:1/proxy")
        assert urllib.parse.parse_qs(urllib.parse.urlparse(link).query)["url"] == ["rerun+http://127.0.0.1:1/proxy"]
    finally:
        viewer.stop()
    assert not reachable(viewer.url)


def test_runs_link_to_the_viewer(tmp_path, small_cfg, isolated_home) -> None:
    s = Settings(data_dir=tmp_path / "data", rerun_web_port=free_port(), rerun_grpc_port=free_port())
    app = create_app(s, small_cfg, loop_factory=fake_factory(), rerun=True)
    with TestClient(app, base_url="http://127.0.0.1") as c:
        health = c.get("/api/health").json()
        assert health["rerun_url"] == f"http://127.0.0.1:{s.rerun_web_port}/"
        run_id = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0}).json()["id"]
        live = c.get(f"/api/runs/{run_id}").json()["links"]["rerun"]
        proxy = f"rerun+http://127.0.0.1:{s.rerun_grpc_port}/proxy"
        assert urllib.parse.parse_qs(urllib.parse.urlparse(live).query)["url"] == [proxy]  # the live stream
        c.post(f"/api/runs/{run_id}/stop")
        wait_status(c, run_id, {"stopped"})
        time.sleep(0.2)
        ended = c.get(f"/api/runs/{run_id}").json()["links"]["rerun"]
        rrd = urllib.parse.parse_qs(urllib.parse.urlparse(ended).query)["url"][0]
        assert rrd.endswith(f"/api/runs/{run_id}/recording")  # the recording file
        origin = f"http://127.0.0.1:{s.rerun_web_port}"
        r = c.get(f"/api/runs/{run_id}/recording", headers={"Origin": origin})
        assert r.status_code == 200 and r.headers["access-control-allow-origin"] == origin
        other = c.get(f"/api/runs/{run_id}/recording", headers={"Origin": "http://evil.example"})
        assert "access-control-allow-origin" not in other.headers
    assert not reachable(health["rerun_url"])  # stopped with the server
