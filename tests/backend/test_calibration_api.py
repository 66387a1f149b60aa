"""The furnace's calibration memory over REST: a finished run's calibration is kept, the next run's plan gets it
(``control.plan_parameters``), ``GET`` shows it and ``DELETE`` (token-guarded) forgets it."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import FakeFactory, FakeLoop, wait_status

TOKEN = "s3cret-token-0123456"
LEARNT = {"lamp_efficiency": {"value": -0.12, "sigma": 0.01},  # learnt
          "emissivity": {"value": -0.2, "sigma": 0.09}}  # sigma still near the prior's 0.1: not learnt


class LearningLoop(FakeLoop):
    def metrics(self) -> dict[str, Any]:
        return {**super().metrics(), "calibration": LEARNT}


class LearningFactory(FakeFactory):
    def __init__(self) -> None:
        super().__init__()
        self.seen: list[Any] = []

    def __call__(self, cfg: Any, scenario: Any, *, budget: Any = None) -> FakeLoop:
        self.seen.append(scenario)
        return LearningLoop(cfg, scenario)


def _run(c: TestClient, headers: dict[str, str]) -> str:
    r = c.post("/api/runs", json={"duration": 2.0, "speed": "max", "reference": {"setpoint": 900.0, "t_E": 1.5}},
               headers=headers)
    assert r.status_code == 201, r.text
    run_id = r.json()["id"]
    wait_status(c, run_id, {"finished"})
    return run_id


def test_a_second_run_plans_with_what_the_first_learnt(tmp_path, small_cfg) -> None:
    factory = LearningFactory()
    settings = Settings(data_dir=tmp_path / "data", api_token=TOKEN)
    auth = {"X-API-Token": TOKEN}
    with TestClient(create_app(settings, small_cfg, loop_factory=factory), base_url="http://127.0.0.1") as c:
        assert c.get("/api/furnace/calibration").json()["plants"] == []
        first = _run(c, auth)
        assert factory.seen[-1].control.plan_parameters is None  # nothing learnt yet: the nominal model
        plants = c.get("/api/furnace/calibration").json()["plants"]
        assert len(plants) == 1 and "simulated" in plants[0]["plant"]
        params = plants[0]["parameters"]
        assert set(params) == {"lamp_efficiency"}
        assert params["lamp_efficiency"]["value"] == -0.12 and params["lamp_efficiency"]["runs"] == [first]
        second = _run(c, auth)
        learnt = factory.seen[-1].control.plan_parameters
        assert learnt is not None and learnt.lamp_efficiency == -0.12 and learnt.emissivity == 0.0
        # the run's own scenario says what its plan used
        assert c.get(f"/api/runs/{second}").json()["scenario"]["control"]["plan_parameters"]["lamp_efficiency"] == -0.12
        assert c.delete("/api/furnace/calibration").status_code == 401  # forgetting needs the token
        reset = c.delete("/api/furnace/calibration", headers=auth)
        assert reset.status_code == 200 and reset.json()["plants"] == []
        _run(c, auth)
        assert factory.seen[-1].control.plan_parameters is None
