"""Hardening finding 9 (issue 15's list; issue 16 owns it): absurd runs were accepted.

Before: ``POST /api/runs`` started a 0 s step to 1300 K, t_E = 1.2 s or 300 -> 1300 K in 1 s; the run
went on with every group at 100 %, a 77 % mean error and nothing said; a setpoint of 301 K "finished"
at 471 K with the lamps off.  Now the reference is simulated on the twin's model at full power and
with the lamps off (``twin.control.feasibility``) before the run starts: far beyond the furnace, a 422
whose message names the time and the shortfall; a little beyond, a warning.  The real loop factory
(``DefaultLoopFactory``) with ``small_config``; nothing is started, so no feedforward is solved."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import wait_model_ready


@pytest.fixture(scope="module")
def client(tmp_path_factory, small_cfg):
    with TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("absurd")), small_cfg),
                    base_url="http://127.0.0.1") as c:
        wait_model_ready(c)  # during the warm-up a POST is queued and checked later (test_warm_up.py)
        yield c


@pytest.mark.parametrize("reference, when", [
    ({"points": [[0.0, 1300.0]]}, "at t = 0.0 s"),  # a 0 s step to 1300 K
    ({"setpoint": 1100.0, "t_E": 1.2}, "at t = 1.2 s"),  # t_E = 1.2 s
    ({"points": [[1.0, 1300.0]]}, "at t = 1.0 s"),  # 300 -> 1300 K in 1 s
])
def test_finding_09_absurd_runs_refused(client, reference, when) -> None:
    r = client.post("/api/runs", json={"reference": reference})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert "cannot follow" in detail and when in detail and "K short" in detail, detail
    assert client.get("/api/runs").json() == []  # nothing was started


def test_finding_09_a_setpoint_the_lamps_off_state_exceeds_is_refused(client) -> None:
    r = client.post("/api/runs", json={"reference": {"setpoint": 301.0, "t_E": 120.0}})
    assert r.status_code == 422 and "lamps off" in r.json()["detail"], r.text
    assert client.get("/api/runs").json() == []


def test_finding_09_the_page_asks_before_it_starts(client) -> None:
    """POST /api/feasibility: the verdict the start would get, for the form's warning."""
    steep = client.post("/api/feasibility", json={"reference": {"setpoint": 1100.0, "t_E": 20.0}}).json()
    assert steep["verdict"] == "warn" and "K short" in steep["messages"][0] and "at t = " in steep["messages"][0]
    assert steep["hold_range"][0] > 400.0 and len(steep["best"]["t"]) == len(steep["best"]["T"]) > 10
    absurd = client.post("/api/feasibility", json={"reference": {"setpoint": 1100.0, "t_E": 1.2}}).json()
    assert absurd["verdict"] == "refuse" and "at t = 1.2 s" in absurd["messages"][0]
    assert client.post("/api/feasibility", json={}).json()["verdict"] == "ok"  # the paper's run
    invalid = client.post("/api/feasibility", json={"duration": 1e6})  # an invalid scenario: the start's 422
    assert invalid.status_code == 422 and invalid.json()["detail"][0]["loc"][-1] == "duration"


def test_the_check_uses_what_the_twin_has_learnt(client) -> None:
    """Issue 26: POST /api/feasibility on the model with the scenario's learnt parameters (a server fills them in
    from its calibration memory): lamps learnt 50 % weaker hold 1187 K instead of 1430 K (small furnace), and
    1250 K is refused with that bound named."""
    body = {"reference": {"setpoint": 1250.0, "t_E": 120.0}}
    nominal = client.post("/api/feasibility", json=body).json()
    weak = client.post("/api/feasibility", json={**body, "control": {"plan_parameters": {"lamp_efficiency": -0.5}}})
    weak_json = weak.json()
    assert nominal["verdict"] != "refuse" and nominal["hold_range"][1] > 1400.0
    assert weak_json["hold_range"][1] < 1200.0 and weak_json["verdict"] == "refuse"
    assert f"{weak_json['hold_range'][1]:.0f} K" in " ".join(weak_json["messages"])
