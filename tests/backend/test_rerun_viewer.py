"""The server's rerun web viewer (issue 14, part 1): rerun's own ``--serve-web`` child on loopback only
(``rr.serve_web_viewer`` would listen on 0.0.0.0: stack-notes.md), with its memory limits, stopped with the
server; runs link to it and their recording may be read from its origin."""

from __future__ import annotations

import time
import urllib.parse
from pathlib import Path

import httpx
import pytest
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
        assert health["rerun_url"] == "http://127.0.0.1/rerun/"  # served by this server, offline
        run_id = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0}).json()["id"]
        live = c.get(f"/api/runs/{run_id}").json()["links"]["rerun"]
        proxy = f"rerun+http://127.0.0.1:{s.rerun_grpc_port}/proxy"
        assert live.startswith("http://127.0.0.1/rerun/?url=")
        assert urllib.parse.parse_qs(urllib.parse.urlparse(live).query)["url"] == [proxy]  # the live stream
        c.post(f"/api/runs/{run_id}/stop")
        wait_status(c, run_id, {"stopped"})
        time.sleep(0.2)
        ended = c.get(f"/api/runs/{run_id}").json()["links"]["rerun"]
        rrd = urllib.parse.parse_qs(urllib.parse.urlparse(ended).query)["url"][0]
        assert rrd.endswith(f"/api/runs/{run_id}/recording.rrd")  # the recording file, named so rerun opens it
        assert c.get(rrd).content[:4] == b"RRF2"  # rerun's file magic
        origin = f"http://127.0.0.1:{s.rerun_web_port}"
        r = c.get(f"/api/runs/{run_id}/recording", headers={"Origin": origin})
        assert r.status_code == 200 and r.headers["access-control-allow-origin"] == origin
        other = c.get(f"/api/runs/{run_id}/recording", headers={"Origin": "http://evil.example"})
        assert "access-control-allow-origin" not in other.headers
        # the viewer's page from this server: nothing from other sites, and a policy that forbids it
        page = c.get("/rerun/")
        assert page.status_code == 200 and "re_viewer.js" in page.text
        for other_site in ("fonts.googleapis.com", "fonts.gstatic.com", "fifteen-thirtyeight.rerun.io"):
            assert other_site not in page.text
        csp = page.headers["content-security-policy"]
        assert "default-src 'self'" in csp and f"connect-src 'self' http://127.0.0.1:{s.rerun_grpc_port};" in csp
        js = c.get("/rerun/re_viewer.js")
        assert js.status_code == 200 and "javascript" in js.headers["content-type"]
        assert c.get("/rerun/no-such-file.js").status_code == 404
    assert not reachable(f"http://127.0.0.1:{s.rerun_web_port}/")  # stopped with the server


@pytest.mark.browser
def test_the_rerun_links_open_the_live_stream_and_the_recording_offline(tmp_path, small_cfg, isolated_home, browser,
                                                                      artifacts) -> None:
    """"Open in rerun" in chromium, while the run goes and once it ended: the viewer comes from this server, connects
    to the live gRPC proxy, then reads the run's .rrd, and asks no other site for anything (fonts, analytics)."""
    from backend.core.threaded_server import ThreadedServer

    s = Settings(data_dir=tmp_path / "data", rerun_web_port=free_port(), rerun_grpc_port=free_port())
    with ThreadedServer(create_app(s, small_cfg, loop_factory=fake_factory(), rerun=True), free_port()) as srv:
        run_id = httpx.post(f"{srv.url}/api/runs", json={"duration": 600.0, "speed": 1.0}, timeout=30).json()["id"]
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        requests: list[str] = []
        answered: dict[str, int] = {}
        page.on("request", lambda r: requests.append(r.url))
        page.on("response", lambda r: answered.__setitem__(r.url, r.status))

        def wait_for(what: str) -> bool:
            end = time.monotonic() + 120  # the viewer's WebAssembly (tens of MB) loads first
            while not any(u.startswith(what) for u in requests) and time.monotonic() < end:
                page.wait_for_timeout(500)
            return any(u.startswith(what) for u in requests)

        live = httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()["links"]["rerun"]
        assert live.startswith(f"{srv.url}/rerun/?url=rerun%2Bhttp")
        page.goto(live, timeout=120_000)
        assert wait_for(f"http://127.0.0.1:{s.rerun_grpc_port}/"), f"no request to the live proxy: {requests[:20]}"
        httpx.post(f"{srv.url}/api/runs/{run_id}/stop", timeout=30)
        end = time.monotonic() + 60
        while httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()["status"] not in {"stopped", "error"}:
            assert time.monotonic() < end
            time.sleep(0.1)
        time.sleep(0.3)
        link = httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()["links"]["rerun"]
        page.goto(link, timeout=120_000)
        rrd = f"{srv.url}/api/runs/{run_id}/recording.rrd"
        assert wait_for(rrd), f"the viewer never asked for the recording; requests: {requests[-20:]}"
        page.wait_for_timeout(2000)
        assert answered.get(rrd) == 200, answered.get(rrd)
        elsewhere = [u for u in requests if not u.startswith(("http://127.0.0.1", "data:", "blob:"))]
        assert not elsewhere, elsewhere
        page.close()
