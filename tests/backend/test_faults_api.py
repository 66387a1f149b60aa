"""``PUT /api/runs/{id}/faults`` and what a run reports about its faults (issue 14, part 2).

The plumbing (status codes, validation against the furnace's TCs and lamp groups) with the fast stand-in
loop, which has no simulated furnace to inject into (422 saying so); the whole path with the real closed
loop on small_config: faults from the scenario and from a PUT (times from now) in force with run times,
the injection and the twin's detection in ``fault_events`` and the events, kept in ``faults.json`` and in
the changes after the run ended.
"""

from __future__ import annotations

import json
import time

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import fake_factory, wait_status


@pytest.mark.parametrize(("body", "needle"), [
    ([{"target": "TC5", "kind": "stuck"}], "TC1/TC2/TC3/TC4"),
    ([{"target": "T9x", "kind": "failed"}], "lamp group of this furnace"),
    ([{"target": "TC1", "kind": "offset"}], "needs a value"),
    ([{"target": "T1h", "kind": "derate", "value": 1.5}], "value: at most 1"),
    ([{"target": "TC1", "kind": "stuck", "at": -1.0}], "at"),
    ({"target": "TC1", "kind": "stuck"}, "list"),
])
def test_bad_fault_lists_are_refused_with_the_reason(tmp_path, small_cfg, body, needle) -> None:
    app = create_app(Settings(data_dir=tmp_path), small_cfg, loop_factory=fake_factory())
    with TestClient(app, base_url="http://127.0.0.1") as c:
        run_id = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0}).json()["id"]
        r = c.put(f"/api/runs/{run_id}/faults", json=body)
        assert r.status_code == 422 and needle in r.text, r.text
        assert c.put("/api/runs/nope/faults", json=[]).status_code == 404
        # the stand-in loop has no simulated furnace: the change is refused, the run goes on
        r = c.put(f"/api/runs/{run_id}/faults", json=[{"target": "TC1", "kind": "stuck"}])
        assert r.status_code == 422 and "simulated furnace" in r.text
        c.post(f"/api/runs/{run_id}/stop")
        wait_status(c, run_id, {"stopped"})
        assert c.put(f"/api/runs/{run_id}/faults", json=[]).status_code == 409


def test_faults_of_a_real_run_from_scenario_and_put(tmp_path, small_cfg) -> None:
    scenario = {"duration": 30.0, "speed": 5.0, "reference": {"setpoint": 800.0, "t_E": 10.0},
                "faults": [{"at": 3.0, "target": "TC1", "kind": "dropout"}]}
    app = create_app(Settings(data_dir=tmp_path, change_timeout_s=60.0), small_cfg)
    with TestClient(app, base_url="http://127.0.0.1") as c:
        r = c.post("/api/runs", json=scenario)
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        end = wait_status(c, run_id, {"running"})
        assert end["faults"] == [{**scenario["faults"][0], "value": None}]
        while (c.get(f"/api/runs/{run_id}").json()["latest"] or {}).get("t", 0.0) < 5.0:
            time.sleep(0.05)
        offset = [{"at": 1.0, "target": "TC3", "kind": "offset", "value": 12.0}]
        put = c.put(f"/api/runs/{run_id}/faults", json=offset)
        assert put.status_code == 200 and put.json()["status"] == "applied", put.text
        t_put = put.json()["applied_t"]
        now = c.get(f"/api/runs/{run_id}").json()
        assert now["faults"] == [{"at": pytest.approx(t_put + 1.0), "target": "TC3", "kind": "offset", "value": 12.0}]
        body = wait_status(c, run_id, {"finished", "error"})
        assert body["status"] == "finished", body["error"]
        texts = [e["text"] for e in body["fault_events"]]
        assert texts[0].startswith("fault injected: TC1 dropout at t = 3.0 s")
        assert any(t.startswith("fault detected: TC1 gives no reading") for t in texts)
        assert any(t.startswith("faults cleared at") and "TC1 dropout" in t for t in texts)
        assert any(t.startswith("fault injected: TC3 offset 12 K") for t in texts)
        # after the end: the last faults in force from the changes, the events from faults.json
        assert body["faults"][0]["at"] == pytest.approx(t_put + 1.0)
        saved = json.loads((tmp_path / "runs" / run_id / "faults.json").read_text())
        assert [e["text"] for e in saved["events"]] == texts
        assert body["changes"][0]["kind"] == "faults" and body["changes"][0]["status"] == "applied"
