"""Issue 15: hostile and careless input, cross-site requests, resource limits.

One test (or a few) per finding of the issue, named after it; the note in docs/hardening.md lists the
before/after evidence.  These use the fast stand-in loop (FakeLoop) where the finding is about the
server; the planning, estimator and disk findings have their own files (test_hardening_*.py).
"""

from __future__ import annotations

import json
import time

import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError

from backend.app import create_app
from backend.core.settings import MIN_TOKEN_LENGTH, Settings
from conftest import fake_factory, wait_status

LOOPBACK = "http://127.0.0.1"
WS = "ws://127.0.0.1"  # TestClient's websockets go to ws://testserver unless the URL is absolute
TOKEN = "t0ken-of-sixteen-chars"


def client(tmp_path, cfg, **settings) -> TestClient:
    s = Settings(data_dir=tmp_path / "data", viser_port=0, **settings)
    return TestClient(create_app(s, cfg, loop_factory=fake_factory()), base_url=LOOPBACK)


def post_raw(c: TestClient, path: str, text: str, **headers: str):
    return c.post(path, content=text.encode(), headers={"Content-Type": "application/json", **headers})


# ---- finding 3: NaN, Infinity or 1e999 in a float field gave a 500 ----
@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e999"])
@pytest.mark.parametrize("template", [
    '{{"duration": {v}}}',
    '{{"reference": {{"setpoint": {v}, "t_E": 60}}}}',
    '{{"reference": {{"points": [[0, 400], [10, {v}]]}}}}',
    '{{"oscillation": {{"enabled": true, "period": {v}}}}}',
    '{{"tc4": [0.5, {v}]}}',
    '{{"mismatch": {{"alpha": {v}}}}}',
    '{{"speed": {v}}}',
])
def test_finding_03_non_finite_numbers_are_422(tmp_path, small_cfg, literal, template) -> None:
    with client(tmp_path, small_cfg) as c:
        r = post_raw(c, "/api/runs", template.format(v=literal))
        assert r.status_code == 422, r.text
        body = r.json()  # valid JSON (the old 500 came from encoding the echoed NaN / inf)
        assert "finite" in json.dumps(body) or "valid number" in json.dumps(body), body
        assert c.get("/api/runs").json() == []  # nothing started


def test_finding_03_non_finite_in_live_changes_are_422(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg) as c:
        run_id = c.post("/api/runs", json={"duration": 30.0, "speed": 1.0}).json()["id"]
        wait_status(c, run_id, {"running"})
        r = post_raw(c, f"/api/runs/{run_id}/reference", '{"setpoint": NaN, "t_E": 10}')
        assert r.status_code == 405  # POST is not the method; the PUTs below are
        r = c.put(f"/api/runs/{run_id}/reference", content=b'{"setpoint": 1e999, "t_E": 10}',
                  headers={"Content-Type": "application/json"})
        assert r.status_code == 422 and r.json()["detail"][0]["input"] == "Infinity"
        r = c.put(f"/api/runs/{run_id}/oscillation", content=b'{"enabled": true, "amplitude": NaN}',
                  headers={"Content-Type": "application/json"})
        assert r.status_code == 422 and r.json()["detail"][0]["input"] == "NaN"
        c.post(f"/api/runs/{run_id}/stop")
        wait_status(c, run_id, {"stopped", "finished"})


# ---- finding 13 (part): "speed": true was read as 1.0 ----
@pytest.mark.parametrize("body", [{"speed": True}, {"duration": True}, {"seed": True}, {"tc4": [0.5, False]},
                                  {"speed": "2"}, {"reference": {"setpoint": "900"}}])
def test_finding_13_booleans_and_strings_are_not_numbers(tmp_path, small_cfg, body) -> None:
    with client(tmp_path, small_cfg) as c:
        r = c.post("/api/runs", json=body)
        assert r.status_code == 422, r.text
    from twin.scenario import parse_scenario

    with pytest.raises(ValidationError):
        parse_scenario(body)  # the CLI's scenario files too


# ---- finding 5: cross-site requests and DNS rebinding ----
def test_finding_05_text_plain_post_is_refused(tmp_path, small_cfg) -> None:
    """A web page can POST text/plain without a preflight: such a body never reaches a route."""
    with client(tmp_path, small_cfg) as c:
        r = c.post("/api/runs", content=b'{"duration": 5}', headers={"Content-Type": "text/plain"})
        assert r.status_code == 415, r.text
        r = c.post("/api/runs", content=b"duration=5", headers={"Content-Type": "application/x-www-form-urlencoded"})
        assert r.status_code == 415
        assert c.get("/api/runs").json() == []


def test_finding_05_foreign_origin_is_refused(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg) as c:
        r = c.post("/api/runs", json={"duration": 5.0}, headers={"Origin": "http://evil.example"})
        assert r.status_code == 403 and "evil.example" in r.json()["detail"]
        assert c.get("/api/runs").json() == []
        # the dashboard's own origin (as the browser reached it) and no Origin (curl) are fine
        ok = c.post("/api/runs", json={"duration": 0.5}, headers={"Origin": "http://127.0.0.1"})
        assert ok.status_code == 201, ok.text
        assert c.post("/api/runs", json={"duration": 0.5}).status_code == 201
        for run in c.get("/api/runs").json():
            wait_status(c, run["id"], {"finished"})
        # a stop is a mutation too: a foreign page cannot stop a run
        run_id = c.post("/api/runs", json={"duration": 30.0, "speed": 1.0}).json()["id"]
        assert c.post(f"/api/runs/{run_id}/stop", headers={"Origin": "http://evil.example"}).status_code == 403
        assert c.get(f"/api/runs/{run_id}").json()["status"] in ("queued", "starting", "running")
        c.post(f"/api/runs/{run_id}/stop")
        wait_status(c, run_id, {"stopped", "finished"})


def test_finding_05_configured_origin_is_allowed(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg, allowed_origins=["https://proxy.lab"]) as c:
        r = c.post("/api/runs", json={"duration": 0.5}, headers={"Origin": "https://proxy.lab"})
        assert r.status_code == 201, r.text
        wait_status(c, r.json()["id"], {"finished"})


def test_finding_05_foreign_host_is_refused(tmp_path, small_cfg) -> None:
    """DNS rebinding: a page of evil.example whose name now points at 127.0.0.1 sends Host: evil.example."""
    with client(tmp_path, small_cfg) as c:
        for path in ("/api/health", "/api/runs", "/", "/docs"):
            r = c.get(path, headers={"Host": "evil.example:8000"})
            assert r.status_code == 421, (path, r.status_code)
        assert c.post("/api/runs", json={}, headers={"Host": "evil.example"}).status_code == 421
        for host in ("127.0.0.1:8000", "localhost:8000", "[::1]:8000", "127.0.0.2"):
            assert c.get("/api/health", headers={"Host": host}).status_code == 200, host
    with client(tmp_path, small_cfg, allowed_hosts=["furnace.lab"]) as c:
        assert c.get("/api/health", headers={"Host": "furnace.lab:8000"}).status_code == 200


def test_finding_05_stream_refuses_foreign_origin(tmp_path, small_cfg) -> None:
    from starlette.websockets import WebSocketDisconnect

    with client(tmp_path, small_cfg) as c:
        run_id = c.post("/api/runs", json={"duration": 0.5}).json()["id"]
        wait_status(c, run_id, {"finished"})
        with pytest.raises(WebSocketDisconnect):  # TestClient: a denial before accept
            with c.websocket_connect(f"{WS}/api/runs/{run_id}/stream", headers={"Origin": "http://evil.example"}) as ws:
                ws.receive_text()
        with c.websocket_connect(f"{WS}/api/runs/{run_id}/stream", headers={"Origin": "http://127.0.0.1"}) as ws:
            assert json.loads(ws.receive_text())["run_id"] == run_id


# ---- finding 6: no body limit; the body was parsed before the token check ----
def test_finding_06_large_body_is_413_before_parsing_and_auth(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg, api_token=TOKEN, max_body_bytes=64 * 1024) as c:
        big = b'{"reference": {"points": [' + b"[1, 400]," * 20000 + b'[2, 400]]}}'
        t0 = time.perf_counter()
        r = c.post("/api/runs", content=big, headers={"Content-Type": "application/json"})  # no token
        assert r.status_code == 413, r.text
        assert "64" in r.json()["detail"] or "65536" in r.json()["detail"]

        def chunks():
            for _ in range(100):
                yield b" " * 1024

        r = c.post("/api/runs", content=chunks(), headers={"Content-Type": "application/json"})  # chunked
        assert r.status_code == 413
        assert time.perf_counter() - t0 < 10.0


def test_finding_06_validation_errors_do_not_echo_large_inputs(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg) as c:
        r = c.post("/api/runs", json={"reference": {"setpoint": "x" * 100_000}})
        assert r.status_code == 422
        assert len(r.content) < 2000, len(r.content)
        r = c.post("/api/runs", json={"reference": {"points": [[i, "hot"] for i in range(900)]}})
        assert r.status_code == 422 and len(r.content) < 10_000, len(r.content)


# ---- finding 7: reference point lists had no cap; lists returned whole scenarios ----
def test_finding_07_reference_points_are_capped(tmp_path, small_cfg) -> None:
    from twin.limits import MAX_REFERENCE_POINTS

    pts = [[float(i), 400.0] for i in range(MAX_REFERENCE_POINTS + 1)]
    with client(tmp_path, small_cfg) as c:
        r = c.post("/api/runs", json={"reference": {"points": pts}})
        assert r.status_code == 422 and "at most" in r.text
        assert c.get("/api/furnace").json()["limits"]["reference"]["points"]["count"]["max"] == MAX_REFERENCE_POINTS
        r = c.post("/api/runs", json={"reference": {"points": pts[:MAX_REFERENCE_POINTS]}, "duration": 0.5})
        assert r.status_code == 201, r.text


def test_finding_07_run_list_holds_summaries(tmp_path, small_cfg) -> None:
    pts = [[float(i), 400.0] for i in range(1000)]
    with client(tmp_path, small_cfg) as c:
        ids = [c.post("/api/runs", json={"reference": {"points": pts}, "duration": 0.5}).json()["id"]
               for _ in range(2)]
        for run_id in ids:
            wait_status(c, run_id, {"finished"})
        listing = c.get("/api/runs")
        assert len(listing.content) < 4000, len(listing.content)  # two whole scenarios would be ~30 kB
        row = listing.json()[0]
        ref = row["scenario"]["reference"]
        assert ref == {"points": 1000, "t_E": 999.0, "setpoint": 400.0}
        assert row["scenario"]["oscillation"]["enabled"] is False  # what the dashboard's list shows
        assert len(c.get(f"/api/runs/{ids[0]}").json()["scenario"]["reference"]["points"]) == 1000  # detail: whole


# ---- finding 12: a token on a non-loopback address did not protect reads; any length accepted ----
def test_finding_12_short_tokens_are_refused() -> None:
    with pytest.raises(ValidationError, match=str(MIN_TOKEN_LENGTH)):
        Settings(api_token="s3cret")
    assert Settings(api_token="x" * MIN_TOKEN_LENGTH).api_token
    assert Settings(api_token="").api_token is None  # an empty variable means no token


def test_finding_12_short_token_refused_by_serve(monkeypatch, small_cfg) -> None:
    from backend.server import serve

    monkeypatch.setenv("FURNACE_TWIN_API_TOKEN", "short")
    assert serve(small_cfg, host="0.0.0.0", port=0, viser_port=0) == 2


def test_finding_12_reads_need_the_token_beyond_loopback(tmp_path, small_cfg) -> None:
    from starlette.websockets import WebSocketDisconnect

    with client(tmp_path, small_cfg, host="0.0.0.0", api_token=TOKEN) as c:
        auth = {"Authorization": f"Bearer {TOKEN}"}
        run_id = c.post("/api/runs", json={"duration": 0.5}, headers=auth).json()["id"]
        wait_status(type("C", (), {"get": lambda self, p: c.get(p, headers=auth)})(), run_id, {"finished"})
        for path in ("/api/runs", f"/api/runs/{run_id}", f"/api/runs/{run_id}/timeseries",
                     f"/api/runs/{run_id}/recording", f"/api/runs/{run_id}/metrics", "/api/furnace"):
            assert c.get(path).status_code == 401, path
            assert c.get(path, headers={"X-API-Token": "wrong-token-of-16+chars"}).status_code == 401, path
            assert c.get(path, headers=auth).status_code == 200, path
        health = c.get("/api/health")  # liveness stays public: it tells the dashboard to ask for the token
        assert health.status_code == 200 and health.json()["auth_required"] is True
        assert health.json()["reads_need_token"] is True
        with pytest.raises(WebSocketDisconnect):
            with c.websocket_connect(f"ws://127.0.0.1/api/runs/{run_id}/stream") as ws:
                ws.receive_text()
        with c.websocket_connect(f"{WS}/api/runs/{run_id}/stream",
                                 subprotocols=["furnace-twin", f"token.{TOKEN}"]) as ws:
            assert json.loads(ws.receive_text())["run_id"] == run_id
            assert ws.accepted_subprotocol == "furnace-twin"  # the token is not echoed
    with client(tmp_path, small_cfg, api_token=TOKEN) as c:  # on loopback reads stay open, changes need it
        assert c.get("/api/runs").status_code == 200
        assert c.post("/api/runs", json={"duration": 0.5}).status_code == 401


# ---- finding 11: /docs and /redoc loaded swagger-ui, redoc and fonts from a CDN ----
def test_finding_11_api_docs_without_cdn(tmp_path, small_cfg) -> None:
    import re

    with client(tmp_path, small_cfg) as c:
        for page in ("/docs", "/redoc"):
            html = c.get(page).text
            urls = re.findall(r'(?:src|href)="([^"]+)"', html) + re.findall(r"url: '([^']+)'", html)
            assert urls, page
            assert not [u for u in urls if u.startswith(("http:", "https:", "//"))], (page, urls)
            assert "cdn" not in html and "googleapis" not in html, page
            for u in urls:
                if u.startswith("/docs-assets/"):
                    r = c.get(u)
                    assert r.status_code == 200 and len(r.content) > 1000, u
        assert c.get("/docs-assets/../settings.py").status_code == 404
        assert c.get("/openapi.json").json()["info"]["title"] == "furnace-twin"
