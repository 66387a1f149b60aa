"""REST status codes and the run lifecycle plumbing, with a fast stand-in loop (conftest.FakeLoop).

The physics of the real closed loop is exercised in test_lifecycle_real.py; here the loop is
the conftest's first-order lag, so each test runs in well under a second.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import fake_factory, stream_frames, wait_status

TOKEN = "s3cret-token-0123456"  # at least backend.core.settings.MIN_TOKEN_LENGTH characters


def make_client(tmp_path: Path, cfg, factory=None, **settings) -> TestClient:
    s = Settings(data_dir=tmp_path / "data", **settings)
    return TestClient(create_app(s, cfg, loop_factory=factory or fake_factory()), base_url="http://127.0.0.1")


def test_lifecycle_with_changes_visible_in_frames(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        assert c.get("/api/health").json()["status"] == "ok"
        r = c.post("/api/runs", json={"duration": 6.0, "speed": 5.0,
                                      "reference": {"setpoint": 900.0, "t_E": 3.0}})
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        changed: set[str] = set()

        def change(f: dict) -> None:
            if "reference" not in changed and f["t"] >= 1.0:
                ch = c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 1000.0, "t_E": 1.5})
                assert ch.status_code == 200, ch.text
                assert ch.json()["status"] == "applied"
                changed.add("reference")
            if "oscillation" not in changed and f["t"] >= 2.0:
                ch = c.put(f"/api/runs/{run_id}/oscillation",
                           json={"enabled": True, "amplitude": 0.03, "period": 1.0})
                assert ch.status_code == 200, ch.text
                changed.add("oscillation")

        frames = stream_frames(c, run_id, change)
        keys = {"t", "eta", "T_ref", "T_mean_hat", "field", "tc", "tc_hat", "u", "u_ff", "inhomogeneity"}
        assert keys <= frames[0].keys()
        ny, nx = small_cfg.specimen.ny, small_cfg.specimen.nx
        assert len(frames[0]["field"]) == ny and len(frames[0]["field"][0]) == nx
        # the fake reference ramps to 900 K by t_E = 3 s; after the change it heads to 1000 K
        assert max(f["T_ref"] for f in frames) == pytest.approx(1000.0)
        assert all(f["eta"] == 0.0 for f in frames if f["t"] < 2.0)
        # amplitude 0.03 m, period 1 s: samples every 0.1 s reach |eta| >= 0.03 sin(0.4 pi) = 0.0285 m
        assert max(abs(f["eta"]) for f in frames) > 0.028
        assert frames[-1]["status"] == "finished"
        body = wait_status(c, run_id, {"finished"})
        assert [ch["kind"] for ch in body["changes"]] == ["reference", "oscillation"]
        assert all(ch["status"] == "applied" for ch in body["changes"])
        assert body["files"] == {"recording": True, "timeseries": True, "metrics": True}
        assert body["latest"]["t"] == pytest.approx(6.0)
        m = c.get(f"/api/runs/{run_id}/metrics")
        assert m.status_code == 200 and "mean_error_transient_max" in m.json()
        ts = c.get(f"/api/runs/{run_id}/timeseries")
        assert ts.status_code == 200
        npz = np.load(__import__("io").BytesIO(ts.content))
        assert npz["t"][-1] == pytest.approx(6.0) and json.loads(str(npz["scenario"]))["duration"] == 6.0
        assert c.get(f"/api/runs/{run_id}/recording").content[:4] == b"RRF2"  # rerun file magic
        # the run is over: controls answer 409
        assert c.post(f"/api/runs/{run_id}/stop").status_code == 409
        assert c.put(f"/api/runs/{run_id}/oscillation", json={"enabled": False}).status_code == 409
        # a client of an ended run gets its last frame, then the stream closes
        with c.websocket_connect(f"ws://127.0.0.1/api/runs/{run_id}/stream") as ws:
            last = json.loads(ws.receive_text())
            assert last["status"] == "finished" and last["t"] == pytest.approx(6.0)
            from starlette.websockets import WebSocketDisconnect

            with pytest.raises(WebSocketDisconnect):
                ws.receive_text()
        listed = c.get("/api/runs").json()
        assert [r["id"] for r in listed] == [run_id]


def test_stop_keeps_data(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        run_id = c.post("/api/runs", json={"duration": 600.0, "speed": 2.0}).json()["id"]
        wait_status(c, run_id, {"running"})
        time.sleep(0.5)
        r = c.post(f"/api/runs/{run_id}/stop")
        assert r.status_code == 202 and r.json()["status"] == "stopping"
        body = wait_status(c, run_id, {"stopped"})
        # speed 2 for ~0.5 s: about 1 simulated second, far from the 600 s duration
        assert 0.0 < body["latest"]["t"] < 10.0
        assert body["files"]["timeseries"] and body["ended_at"] is not None


def test_404s(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        for method, path, body in [
            ("get", "/api/runs/abc123", None), ("post", "/api/runs/abc123/stop", None),
            ("put", "/api/runs/abc123/reference", {"setpoint": 1000.0}),
            ("put", "/api/runs/abc123/oscillation", {"enabled": True}),
            ("get", "/api/runs/abc123/metrics", None), ("get", "/api/runs/abc123/recording", None),
            ("get", "/api/runs/abc123/timeseries", None), ("get", "/api/runs/..%2F..%2Fetc/recording", None),
        ]:
            r = getattr(c, method)(path, **({"json": body} if body else {}))
            assert r.status_code == 404, (path, r.status_code)
            assert "detail" in r.json()
        from starlette.testclient import WebSocketDenialResponse

        with pytest.raises(WebSocketDenialResponse) as exc:
            with c.websocket_connect("ws://127.0.0.1/api/runs/abc123/stream"):
                pass
        assert exc.value.status_code == 404


def test_422s_name_the_field(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg, max_duration_s=100.0, max_speed=10.0) as c:
        cases = [
            ({"duration": -1}, "duration"),
            ({"speed": "fast"}, "speed"),
            ({"tc4": [2.0, 0.5]}, "tc4"),
            ({"reference": {"setpoint": 5000.0}}, "setpoint"),
            ({"oscillation": {"amplitude": 1.0}}, "amplitude"),
            ({"bogus": 1}, "bogus"),
            ({"duration": 200.0}, "duration"),  # over this server's limit of 100 s
            ({"speed": 50.0, "duration": 10.0}, "speed"),  # over this server's limit of 10
            ({"truth": "model"}, "truth"),  # "independent" or "shared"
        ]
        for body, field in cases:
            r = c.post("/api/runs", json=body)
            assert r.status_code == 422, (body, r.text)
            assert field in r.text, (body, r.text)
        assert c.post("/api/runs", content=b"{not json", headers={"content-type": "application/json"}
                      ).status_code == 422
        run_id = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0}).json()["id"]
        wait_status(c, run_id, {"running"})
        r = c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 100.0})
        assert r.status_code == 422 and "setpoint" in r.text
        r = c.put(f"/api/runs/{run_id}/oscillation", json={"period": 0.0})
        assert r.status_code == 422 and "period" in r.text
        # the fake loop refuses setpoints above 1250 K: the worker's ValueError becomes a 422
        r = c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 1280.0})
        assert r.status_code == 422 and "unreachable" in r.text
        assert c.get(f"/api/runs/{run_id}").json()["status"] == "running"  # the run goes on
        assert c.get(f"/api/runs/{run_id}/metrics").status_code == 409  # no metrics while running
        c.post(f"/api/runs/{run_id}/stop")


def test_429_past_concurrent_runs(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg, max_concurrent_runs=2) as c:
        ids = [c.post("/api/runs", json={"duration": 600.0, "speed": 1.0}).json()["id"] for _ in range(2)]
        r = c.post("/api/runs", json={"duration": 10.0})
        assert r.status_code == 429 and "2 at once" in r.json()["detail"]
        c.post(f"/api/runs/{ids[0]}/stop")
        wait_status(c, ids[0], {"stopped"})
        assert c.post("/api/runs", json={"duration": 1.0}).status_code == 201
        c.post(f"/api/runs/{ids[1]}/stop")


def test_token_guards_every_mutating_endpoint(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg, api_token=TOKEN) as c:
        assert c.get("/api/health").json()["auth_required"] is True
        assert c.post("/api/runs", json={"duration": 1.0}).status_code == 401
        assert c.post("/api/runs", json={"duration": 1.0}, headers={"X-API-Token": "nope"}).status_code == 401
        ok = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0},
                    headers={"Authorization": f"Bearer {TOKEN}"})
        assert ok.status_code == 201
        run_id = ok.json()["id"]
        assert c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 1000.0}).status_code == 401
        assert c.put(f"/api/runs/{run_id}/oscillation", json={"enabled": True}).status_code == 401
        assert c.post(f"/api/runs/{run_id}/stop").status_code == 401
        assert c.get(f"/api/runs/{run_id}").status_code == 200  # reading needs no token
        assert c.post(f"/api/runs/{run_id}/stop", headers={"X-API-Token": TOKEN}).status_code == 202


def test_dashboard_and_plotly_are_served_locally(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        page = c.get("/")
        assert page.status_code == 200 and "/assets/plotly.min.js" in page.text
        assert 'src="http' not in page.text and 'href="http' not in page.text  # nothing from the internet
        js = c.get("/assets/plotly.min.js")
        assert js.status_code == 200 and len(js.content) > 1_000_000  # the full bundle is ~4.6 MB
        assert c.get("/assets/..%2Fpyproject.toml").status_code == 404
        assert c.get("/assets/nothing.js").status_code == 404
        furnace = c.get("/api/furnace").json()
        assert furnace["nx"] == small_cfg.specimen.nx and len(furnace["groups"]) == 6


def test_real_time_factor_paces_the_samples(tmp_path, small_cfg) -> None:
    """speed 2: simulated time advances twice as fast as the wall clock (sample wall stamps)."""
    with make_client(tmp_path, small_cfg) as c:
        run_id = c.post("/api/runs", json={"duration": 4.0, "speed": 2.0}).json()["id"]
        frames = []
        with c.websocket_connect(f"ws://127.0.0.1/api/runs/{run_id}/stream") as ws:
            while True:
                try:
                    frames.append(json.loads(ws.receive_text()))
                except Exception:
                    break
        live = [f for f in frames if f["status"] == "running"]
        sim = live[-1]["t"] - live[0]["t"]
        wall = live[-1]["wall_time"] - live[0]["wall_time"]
        assert sim > 3.0  # nearly the whole 4 s run was streamed
        # pacing is absolute (origin + t / speed), so the error does not grow with the run;
        # 0.15 s covers one scheduling delay of the event loop on a loaded 2-core machine
        assert abs(wall - sim / 2.0) < 0.15, (wall, sim)
        # at 10 samples per simulated second x 2 = 20 samples/s, frames are capped at 20/s
        rate = (len(live) - 1) / wall
        assert 15.0 < rate <= 21.0, rate


def test_points_reference_at_start_and_live(tmp_path, small_cfg) -> None:
    """{"points": [[t, T], ...]} is a reference at the start (times from 0) and as a live change
    (times from the first sample that uses it); the frames' T_ref follows the points."""
    with make_client(tmp_path, small_cfg) as c:
        start = {"points": [[0.0, 300.0], [2.0, 700.0], [3.0, 800.0]]}
        r = c.post("/api/runs", json={"duration": 8.0, "speed": 2.0, "reference": start})  # every sample streamed
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        assert c.get(f"/api/runs/{run_id}").json()["scenario"]["reference"] == start
        replies = []

        def change(f: dict) -> None:
            if not replies and f["t"] >= 4.0:
                replies.append(c.put(f"/api/runs/{run_id}/reference", json={"points": [[1.0, 900.0], [2.0, 950.0]]}))

        frames = stream_frames(c, run_id, change)
        reply = replies[0]
        assert reply.status_code == 200, reply.text
        assert reply.json()["status"] == "applied" and reply.json()["body"] == {"points": [[1.0, 900.0], [2.0, 950.0]]}
        t0 = reply.json()["applied_t"]
        by_t = {round(f["t"], 1): f["T_ref"] for f in frames}
        assert by_t[2.0] == pytest.approx(700.0) and by_t[3.0] == pytest.approx(800.0)
        # the new points count from the sample the change applied at: 900 K one second later, then 950 K
        assert by_t[round(t0 + 1.0, 1)] == pytest.approx(900.0)
        assert frames[-1]["T_ref"] == pytest.approx(950.0)
        body = wait_status(c, run_id, {"finished"})
        assert body["changes"][0]["body"] == {"points": [[1.0, 900.0], [2.0, 950.0]]}
        assert body["changes"][0]["status"] == "applied"


def test_bad_points_get_422_that_says_why(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg) as c:
        bad = [
            ({"points": [[0.0, 900.0], [0.0, 1000.0]]}, "strictly increasing"),
            ({"points": [[5.0, 900.0], [3.0, 1000.0]]}, "strictly increasing"),
            ({"points": [[-1.0, 900.0]]}, ">= 0"),
            ({"points": [[10.0, 2000.0]]}, "2000"),
            ({"points": []}, "at least 1"),
            ({"points": [[1.0, 2.0, 3.0]]}, "at most 2"),
            ({"points": [[1.0, "hot"]]}, "must be a number"),
            ({"points": [[10.0, 1280.0]]}, "unreachable"),  # the (fake) furnace holds at most 1250 K
        ]
        for ref, why in bad:
            r = c.post("/api/runs", json={"duration": 5.0, "reference": ref})
            assert r.status_code == 422, (ref, r.text)
            assert why in r.text, (ref, r.text)
        assert c.get("/api/runs").json() == []  # nothing was started
        run_id = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0}).json()["id"]
        wait_status(c, run_id, {"running"})
        for ref, why in bad:
            r = c.put(f"/api/runs/{run_id}/reference", json=ref)
            assert r.status_code == 422, (ref, r.text)
            assert why in r.text, (ref, r.text)
        body = c.get(f"/api/runs/{run_id}").json()
        assert body["status"] == "running"  # a refused reference never ends the run
        # only the unreachable one reached the loop; it is kept as a rejected change
        assert [(ch["status"], ch["body"]) for ch in body["changes"]] == [("rejected", {"points": [[10.0, 1280.0]]})]
        c.post(f"/api/runs/{run_id}/stop")


def test_points_need_the_token_too(tmp_path, small_cfg) -> None:
    ref = {"points": [[5.0, 900.0]]}
    with make_client(tmp_path, small_cfg, api_token=TOKEN) as c:
        r = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0, "reference": ref})
        assert r.status_code == 401 and "token" in r.json()["detail"]
        assert r.headers["www-authenticate"] == "Bearer"
        ok = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0, "reference": ref},
                    headers={"X-API-Token": TOKEN})
        assert ok.status_code == 201, ok.text
        run_id = ok.json()["id"]
        wait_status(c, run_id, {"running"})
        assert c.put(f"/api/runs/{run_id}/reference", json=ref).status_code == 401
        assert c.put(f"/api/runs/{run_id}/reference", json=ref, headers={"X-API-Token": "wrong"}).status_code == 401
        r = c.put(f"/api/runs/{run_id}/reference", json=ref, headers={"X-API-Token": TOKEN})
        assert r.status_code == 200 and r.json()["status"] == "applied"
        assert c.post(f"/api/runs/{run_id}/stop", headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 202


def test_events_reach_the_stream_at_max_speed(tmp_path, small_cfg) -> None:
    """At speed max most samples are not streamed (frames are capped); the events of skipped samples
    ride on the next frame, so a change's event arrives exactly once."""
    with make_client(tmp_path, small_cfg, stream_max_hz=5.0) as c:
        run_id = c.post("/api/runs", json={"duration": 3000.0, "speed": "max"}).json()["id"]
        replies = []

        def change(f: dict) -> None:
            if not replies and f["t"] > 1.0:
                replies.append(c.put(f"/api/runs/{run_id}/oscillation", json={"enabled": True, "period": 5.0}))
            elif replies and len(replies) == 1 and f["t"] > replies[0].json()["applied_t"] + 50.0:
                replies.append(c.post(f"/api/runs/{run_id}/stop"))

        frames = stream_frames(c, run_id, change)
        assert replies[0].status_code == 200, replies[0].text
        seqs = [f["seq"] for f in frames]
        assert max(b - a for a, b in zip(seqs, seqs[1:], strict=False)) > 10  # samples were skipped
        events = [e for f in frames for e in f["events"]]
        assert [e for e in events if e.startswith("oscillation on")] == [
            f"oscillation on at t = {replies[0].json()['applied_t']:.1f} s"]
