"""A fresh server answers at once while its radiation model warms up (issue 14, part 3).

The ray trace is held back by a gate (``twin.radiation.radiation_model`` replaced by one that reports
progress and waits for the test), so the test does not depend on how long a trace takes: while the
gate is closed ``GET /api/health`` says ``computing`` with the progress, a POST answers 201 with
status ``queued`` within 1 s, and the run starts once the gate opens.  A run whose reference turns
out unreachable once the model is ready ends in ``error`` saying so; a run stopped while queued ends
``stopped``.
"""

from __future__ import annotations

import threading
import time

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from backend.runs.loop_factory import DefaultLoopFactory
from conftest import wait_status


@pytest.fixture
def gated_radiation(monkeypatch, small_radiation):
    """radiation_model() that reports 3 of 13 positions traced, then waits for ``gate.set()``."""
    gate = threading.Event()

    def slow_model(cfg, *, cache_dir=None, progress=False, symmetric=False, on_position=None):
        if on_position is not None:
            for k in (1, 2, 3):
                on_position(k, 13)
        assert gate.wait(120), "the test never opened the gate"
        return small_radiation

    monkeypatch.setattr("twin.radiation.radiation_model", slow_model)
    yield gate
    gate.set()


def _health(c) -> dict:
    r = c.get("/api/health")
    assert r.status_code == 200
    return r.json()


def test_a_post_during_warm_up_is_queued_and_starts_when_ready(tmp_path, small_cfg, gated_radiation) -> None:
    app = create_app(Settings(data_dir=tmp_path), small_cfg, loop_factory=DefaultLoopFactory())
    with TestClient(app, base_url="http://127.0.0.1") as c:
        end = time.monotonic() + 30
        while _health(c)["radiation_progress"]["done"] < 3 and time.monotonic() < end:
            time.sleep(0.02)
        h = _health(c)
        assert h["radiation"] == "computing"
        assert h["radiation_progress"]["stage"] == "ray tracing"
        assert (h["radiation_progress"]["done"], h["radiation_progress"]["total"]) == (3, 13)

        t0 = time.monotonic()
        r = c.post("/api/runs", json={"duration": 1.0, "reference": {"setpoint": 700.0, "t_E": 20.0}})
        elapsed = time.monotonic() - t0
        assert r.status_code == 201, r.text
        assert r.json()["status"] == "queued"
        assert elapsed < 1.0, f"POST took {elapsed:.2f} s during the warm-up"
        run_id = r.json()["id"]
        # the form's check says it cannot tell yet, instead of waiting for the model (and a client's timeout)
        t0 = time.monotonic()
        pending = c.post("/api/feasibility", json={"reference": {"setpoint": 700.0, "t_E": 20.0}})
        assert time.monotonic() - t0 < 1.0 and pending.json()["verdict"] == "pending", pending.text
        assert "loading" in pending.json()["messages"][0]
        time.sleep(0.3)
        assert c.get(f"/api/runs/{run_id}").json()["status"] == "queued"  # nothing can run yet
        # the header's counts: a queued run is not "1 running" (issue 27 item 9)
        assert (_health(c)["active_runs"], _health(c)["queued_runs"]) == (1, 1)

        # with the lamps off the warm holders and walls keep the specimen above 350 K: the last point cannot be
        # held (test_lifecycle_real.py), which only the model can tell
        cold = {"duration": 240.0, "reference": {"points": [[60.0, 900.0], [120.0, 350.0]]}}
        unreachable = c.post("/api/runs", json=cold)
        assert unreachable.status_code == 201  # not checkable before the model is ready
        gated_radiation.set()
        assert wait_status(c, run_id, {"finished", "error"})["status"] == "finished"
        assert _health(c)["radiation"] == "ready"
        bad = wait_status(c, unreachable.json()["id"], {"finished", "error"})
        assert bad["status"] == "error" and "lamps off" in bad["error"], bad
        # once ready, the same reference is refused at once
        again = c.post("/api/runs", json=cold)
        assert again.status_code == 422 and "lamps off" in again.text, again.text


def test_a_run_stopped_while_queued_ends_stopped(tmp_path, small_cfg, gated_radiation) -> None:
    app = create_app(Settings(data_dir=tmp_path), small_cfg, loop_factory=DefaultLoopFactory())
    with TestClient(app, base_url="http://127.0.0.1") as c:
        run_id = c.post("/api/runs", json={"duration": 1.0}).json()["id"]
        # no live change while queued: nothing to check it from yet (issue 27: one sent while starting was applied
        # without the feasibility check of a start)
        change = c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 1050.0, "t_E": 30.0})
        assert change.status_code == 409, change.text
        assert "is queued: live changes are taken once it runs" in change.text, change.text
        assert c.post(f"/api/runs/{run_id}/stop").status_code == 202
        body = wait_status(c, run_id, {"stopped", "error", "finished"}, timeout=30)
        assert body["status"] == "stopped", body
        assert _health(c)["radiation"] == "computing"


def test_a_stalled_trace_is_reported_with_its_reason_and_can_be_retried(monkeypatch, tmp_path, small_cfg,
                                                                       small_radiation) -> None:
    """The page says what failed (the watchdog's reason), and POST /api/radiation/retry starts the warm-up again."""
    from twin.radiation.workers import TraceStalled

    calls = []
    gate = threading.Event()

    def flaky_model(cfg, *, cache_dir=None, progress=False, symmetric=False, on_position=None):
        if symmetric:  # the simulated furnace's own table (also asked by an earlier test's warm-up thread)
            return small_radiation
        calls.append(1)
        if on_position is not None:
            on_position(0, 13)
        if len(calls) == 1:
            raise TraceStalled("ray tracing stalled: worker 123 used no CPU time for 60 s on position 2 of 13")
        if on_position is not None:
            on_position(4, 13)
        assert gate.wait(120), "the test never opened the gate"
        return small_radiation

    monkeypatch.setattr("twin.radiation.radiation_model", flaky_model)
    app = create_app(Settings(data_dir=tmp_path), small_cfg, loop_factory=DefaultLoopFactory())
    try:
        with TestClient(app, base_url="http://127.0.0.1") as c:
            end = time.monotonic() + 30
            while _health(c)["radiation"] == "computing" and time.monotonic() < end:
                time.sleep(0.02)
            h = _health(c)
            assert h["radiation"] == "failed"
            assert h["radiation_progress"]["error"].startswith("ray tracing stalled: worker 123 used no CPU"), h
            before = len(calls)
            r = c.post("/api/radiation/retry")
            assert r.status_code == 202, r.text
            end = time.monotonic() + 30
            while _health(c)["radiation_progress"]["done"] < 4 and time.monotonic() < end:
                time.sleep(0.02)
            h = _health(c)
            assert len(calls) == before + 1
            assert h["radiation"] == "computing" and h["radiation_progress"]["error"] is None
            assert h["radiation_progress"]["remaining_s"] is not None and h["radiation_progress"]["remaining_s"] >= 0
            again = c.post("/api/radiation/retry")
            assert again.status_code == 409 and "computing" in again.text, again.text
            gate.set()
            end = time.monotonic() + 60
            while _health(c)["radiation"] != "ready" and time.monotonic() < end:
                time.sleep(0.05)
            assert _health(c)["radiation"] == "ready"
            assert c.post("/api/radiation/retry").status_code == 409
    finally:
        gate.set()


def test_remaining_seconds_follow_the_pace_of_the_positions() -> None:
    from backend.runs.loop_factory import WarmUpStatus

    now = time.monotonic()
    # 4 of 13 positions in 20 s: 5 s each, 9 left -> 45 s
    st = WarmUpStatus("computing", "ray tracing", done=4, total=13, started=now - 30, stage_started=now - 20)
    assert st.remaining_s == pytest.approx(45.0, abs=0.5)
    assert WarmUpStatus("computing", "ray tracing", done=0, total=13, stage_started=now).remaining_s is None
    assert WarmUpStatus("ready", "ready", done=13, total=13).remaining_s is None
