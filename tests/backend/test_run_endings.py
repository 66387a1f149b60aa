"""How a run ended, for every ending (issue 24): ``status`` and ``status_reason`` in ``GET /api/runs/{id}``, in
``metrics.json`` and in the run's events; ``degraded`` while no thermocouple reading reaches the estimate and as
the ending of a run that was still blind at its end.

The blind runs are real closed loops on small_config (each in its own process, as the server runs them) whose
TC1..TC3 drop out together (injected faults): the twin loses every reading, as when a furnace over OPC UA is
out.  A failing run uses the stand-in loop (one that raises); the furnace lost over OPC UA is
``tests/furnace/test_opcua_realtime.py``'s, an interrupted run ``test_restart.py``'s.
"""

from __future__ import annotations

import dataclasses
import json
import time

from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import FakeFactory, FakeLoop, wait_status

ALL_OUT = [{"at": 2.0, "target": tc, "kind": "dropout"} for tc in ("TC1", "TC2", "TC3")]
BLIND = {"duration": 6.0, "speed": 2.0, "reference": {"setpoint": 500.0, "t_E": 10.0}, "faults": ALL_OUT}


def _metrics(tmp_path, run_id: str) -> dict:
    return json.loads((tmp_path / "runs" / run_id / "metrics.json").read_text())


def _events(c: TestClient, run_id: str) -> list[dict]:
    return c.get(f"/api/runs/{run_id}/series").json()["events"]


def test_a_run_blind_to_its_end_is_degraded_live_and_at_its_end(tmp_path, small_cfg) -> None:
    with TestClient(create_app(Settings(data_dir=tmp_path), small_cfg), base_url="http://127.0.0.1") as c:
        run_id = c.post("/api/runs", json=BLIND).json()["id"]
        live = wait_status(c, run_id, {"degraded", "finished", "error"})
        assert live["status"] == "degraded" and live["ended_at"] is None, live
        assert live["status_reason"].startswith("blind since t = 2.0 s"), live  # 1 s after the last reading
        body = wait_status(c, run_id, {"finished", "degraded", "error", "stopped"}, timeout=180)
        while body["ended_at"] is None:  # the live status, then the ending
            body = c.get(f"/api/runs/{run_id}").json()
        events = _events(c, run_id)
    assert body["status"] == "degraded", body
    reason = "blind from t = 2.0 s to the end (4.0 s without a thermocouple reading in the estimate)"
    assert body["status_reason"] == reason
    saved = _metrics(tmp_path, run_id)
    assert (saved["status"], saved["status_reason"]) == ("degraded", reason)
    blind = [e for e in events if e["text"].startswith("blind since t = 2.0 s")]
    assert blind and blind[0]["level"] == "warn" and "the TCs report no usable value" in blind[0]["text"], events
    assert events[-1]["text"] == f"run ended blind at t = 6.0 s: {reason}" and events[-1]["level"] == "warn"
    assert not any(e["text"].startswith("fault detected: TC") and "dropout" in e["text"] for e in events), \
        "a loss of every TC at once is no TC's dropout"


def test_a_run_whose_readings_came_back_finished_and_says_when_it_was_blind(tmp_path, small_cfg) -> None:
    with TestClient(create_app(Settings(data_dir=tmp_path, change_timeout_s=60.0), small_cfg),
                    base_url="http://127.0.0.1") as c:
        run_id = c.post("/api/runs", json={**BLIND, "duration": 8.0}).json()["id"]
        wait_status(c, run_id, {"degraded"})
        while (c.get(f"/api/runs/{run_id}").json()["latest"] or {}).get("t", 0.0) < 3.5:
            time.sleep(0.05)
        cleared = c.put(f"/api/runs/{run_id}/faults", json=[])
        assert cleared.status_code == 200 and cleared.json()["status"] == "applied", cleared.text
        t_back = cleared.json()["applied_t"]
        running = wait_status(c, run_id, {"running", "finished"})
        assert running["status"] == "running" and running["status_reason"] is None
        body = wait_status(c, run_id, {"finished", "degraded", "error"}, timeout=180)
        events = _events(c, run_id)
    again = [e for e in events if e["text"].startswith("thermocouple readings used again")]
    assert again and again[0]["t"] <= t_back + 0.2, (t_back, events)  # at the first sample with readings
    assert body["status"] == "finished"
    assert body["status_reason"].startswith("blind once, ") and "2.0-" in body["status_reason"], body
    assert _metrics(tmp_path, run_id)["status_reason"] == body["status_reason"]


def test_stopped_and_failed_runs_say_so(tmp_path, small_cfg) -> None:
    class Failing(FakeLoop):
        def step(self):
            if self.t >= 1.0:
                raise RuntimeError("the lamp driver answered nonsense")
            return super().step()

    class Factory(FakeFactory):
        def __call__(self, cfg, scenario, *, budget=None):
            return (Failing if scenario.seed == 13 else FakeLoop)(cfg, scenario, step_cost_s=0.01)

    app = create_app(Settings(data_dir=tmp_path), small_cfg, loop_factory=Factory())
    with TestClient(app, base_url="http://127.0.0.1") as c:
        failing = c.post("/api/runs", json={"duration": 5.0, "seed": 13}).json()["id"]
        failed = wait_status(c, failing, {"error", "finished"})
        stopping = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0}).json()["id"]
        wait_status(c, stopping, {"running"})
        time.sleep(0.5)
        c.post(f"/api/runs/{stopping}/stop")
        stopped = wait_status(c, stopping, {"stopped"})
    assert failed["status"] == "error" and failed["status_reason"] == "RuntimeError: the lamp driver answered nonsense"
    assert _metrics(tmp_path, failing)["status"] == "error"
    assert stopped["status_reason"].startswith("stopped at t = ")
    assert _metrics(tmp_path, stopping)["status_reason"] == stopped["status_reason"]


def test_a_run_being_let_go_says_why_it_ended(tmp_path) -> None:
    """Between the driver setting a run's final status and letting the run go, a request sees the live status:
    its reason must be the ending's, which the database may not hold yet (the suite under load once read
    ``finished`` with ``status_reason`` null in test_a_run_whose_readings_came_back_...).  A going run that is
    degraded says since when it is blind; a run the server does not drive, the database's reason."""
    from backend.api.routes.runs import summary
    from backend.storage.repository import RunRow
    from twin.runs.folder import RunFolder

    class Manager:  # what summary asks of the run manager, for one run
        live_url = None

        def __init__(self, status, ending_reason, blind_since=None) -> None:
            self._status, self._ending, self._blind = status, ending_reason, blind_since

        def status(self, run_id):
            return self._status

        def ending_reason(self, run_id):
            return self._ending

        def latest(self, run_id):
            class Sample:
                snapshot = type("Snap", (), {"blind_since": self._blind})()
            return Sample() if self._blind is not None else None

        def files(self, run_id):
            return RunFolder(tmp_path / run_id)

        def changes(self, run_id):
            return []

    row = RunRow(id="r1", scenario={}, status="running", created_at=0.0, started_at=0.0, ended_at=None,
                 latest=None, metrics=None, error=None)  # read before the ending reached the database
    ended = summary(row, Manager("finished", "blind once, 3.0 s in all: 2.0-5.0 s (the TCs report faults)"))
    assert (ended.status, ended.status_reason) == ("finished", "blind once, 3.0 s in all: 2.0-5.0 s (the TCs "
                                                               "report faults)")
    blind = summary(row, Manager("degraded", None, blind_since=2.0))
    assert blind.status_reason == "blind since t = 2.0 s: no thermocouple reading reaches the estimate"
    stored = dataclasses.replace(row, status="finished", status_reason="blind once, ...")
    assert summary(stored, Manager(None, None)).status_reason == "blind once, ..."
