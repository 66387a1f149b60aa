"""The loaded furnace owns the scenario limits: GET /api/furnace reports them, POST and PUT refuse what lies
outside them (422 naming the field), fields left out take its defaults; GET /api/runs/{id} reports the
reference and oscillation in force.  The furnace here is the default one with eta_max = 30 mm, below the
paper's default amplitude 3 L_h = 48 mm (written as a TOML file with a base, like a user's)."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import free_port
from conftest import fake_factory, wait_status
from twin.config import load_config
from twin.limits import furnace_name

LOW_STROKE = 'base = "default"\n[oscillation]\neta_max = 0.03\n'


@pytest.fixture
def low_stroke(tmp_path):
    path = tmp_path / "low_stroke.toml"
    path.write_text(LOW_STROKE)
    return path


def make_client(tmp_path: Path, furnace: Path, viser: bool = False, **settings) -> TestClient:
    cfg = load_config(furnace)
    s = Settings(data_dir=tmp_path / "data", viser_port=free_port() if viser else 0, **settings)
    return TestClient(create_app(s, cfg, loop_factory=fake_factory(), viser=viser,
                                 furnace_name=furnace_name(cfg, furnace)), base_url="http://127.0.0.1")


def test_furnace_describes_itself_and_every_limit(tmp_path, low_stroke) -> None:
    with make_client(tmp_path, low_stroke, max_duration_s=600.0) as c:
        f = c.get("/api/furnace").json()
    cfg = load_config(low_stroke)
    assert f["name"] == "low_stroke" and f["eta_max"] == 0.03
    assert (f["L_s"], f["W_s"], f["nx"], f["ny"]) == (0.4, 0.2, 26, 17)  # default_furnace.toml's specimen
    assert f["groups"] == [{"name": g.name, "lamps": list(g.lamps)} for g in cfg.lamps.groups]
    assert f["groups"][0] == {"name": "T1h", "lamps": ["h-1", "h-2"]}
    assert f["tc_relative"][1] == [0.5, 0.8] and f["tc_positions"][1] == pytest.approx([0.2, 0.16])  # TC2 in m
    lim = f["limits"]
    assert lim["oscillation"]["amplitude"] == {"min": 0.0, "max": 0.03, "exclusive_min": False, "unit": "m",
                                               "default": 0.03}  # 3 L_h = 48 mm capped at eta_max
    assert lim["duration"]["max"] == 600.0  # this server's limit
    assert lim["reference"]["setpoint"]["min"] == 300.0 and lim["reference"]["setpoint"]["exclusive_min"]
    assert lim["reference"]["points"]["temperature"]["max"] == 1300.0
    assert f["defaults"]["oscillation"] == {"enabled": False, "amplitude": 0.03, "period": 18.0}
    assert lim["truth"] == {"choices": ["independent", "shared"], "default": "independent"}
    assert f["defaults"]["truth"] == "independent"


def test_amplitude_above_eta_max_is_422_on_post_and_put(tmp_path, low_stroke) -> None:
    with make_client(tmp_path, low_stroke) as c:
        r = c.post("/api/runs", json={"duration": 60.0, "oscillation": {"enabled": True, "amplitude": 0.048}})
        assert r.status_code == 422, r.text
        [err] = r.json()["detail"]
        assert err["loc"] == ["body", "oscillation", "amplitude"]
        assert "at most 0.03 m (eta_max of furnace 'low_stroke'), got 0.048 m" in err["msg"]
        assert c.get("/api/runs").json() == []  # nothing was started
        # left out, the amplitude is the furnace's default, which this furnace can do
        r = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0, "oscillation": {"enabled": True}})
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        wait_status(c, run_id, {"running"})
        assert c.get(f"/api/runs/{run_id}").json()["scenario"]["oscillation"]["amplitude"] == 0.03
        r = c.put(f"/api/runs/{run_id}/oscillation", json={"enabled": True, "amplitude": 0.04, "period": 5.0})
        assert r.status_code == 422, r.text
        assert r.json()["detail"][0]["loc"] == ["body", "amplitude"] and "0.03 m" in r.text
        body = c.get(f"/api/runs/{run_id}").json()
        assert body["status"] == "running" and body["changes"] == []  # refused before it reached the run
        r = c.put(f"/api/runs/{run_id}/oscillation", json={"enabled": True, "period": 5.0})
        assert r.status_code == 200 and r.json()["status"] == "applied", r.text
        assert r.json()["body"] == {"enabled": True, "amplitude": 0.03, "period": 5.0}
        assert c.post(f"/api/runs/{run_id}/stop").status_code == 202


def test_run_reports_the_reference_and_oscillation_in_force(tmp_path, small_cfg) -> None:
    """After live changes GET /api/runs/{id} has the new ones (a refused change leaves them); an ended run
    keeps the last ones in force, also after a server restart (from the database)."""
    settings = Settings(data_dir=tmp_path / "data", viser_port=0)
    start = {"duration": 600.0, "speed": 1.0, "reference": {"setpoint": 900.0, "t_E": 3.0}}
    with TestClient(create_app(settings, small_cfg, loop_factory=fake_factory()), base_url="http://127.0.0.1") as c:
        run_id = c.post("/api/runs", json=start).json()["id"]
        wait_status(c, run_id, {"running"})
        body = c.get(f"/api/runs/{run_id}").json()
        assert body["reference"] == {"setpoint": 900.0, "t_E": 3.0}
        assert body["oscillation"] == {"enabled": False, "amplitude": 0.048, "period": 18.0}
        assert c.put(f"/api/runs/{run_id}/reference", json={"points": [[2.0, 1000.0]]}).status_code == 200
        osc = {"enabled": True, "amplitude": 0.02, "period": 4.0}
        assert c.put(f"/api/runs/{run_id}/oscillation", json=osc).status_code == 200
        assert c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 1280.0}).status_code == 422  # unreachable
        body = c.get(f"/api/runs/{run_id}").json()
        assert body["reference"] == {"points": [[2.0, 1000.0]]} and body["oscillation"] == osc
        assert body["scenario"]["reference"] == start["reference"]  # the scenario stays as started
        c.post(f"/api/runs/{run_id}/stop")
        ended = wait_status(c, run_id, {"stopped"})
        assert ended["reference"] == {"points": [[2.0, 1000.0]]} and ended["oscillation"] == osc
    with TestClient(create_app(settings, small_cfg, loop_factory=fake_factory()),
                    base_url="http://127.0.0.1") as c:  # a restarted server
        again = c.get(f"/api/runs/{run_id}").json()
        assert again["reference"] == {"points": [[2.0, 1000.0]]} and again["oscillation"] == osc


def test_3d_view_inputs_come_from_the_furnace(tmp_path, low_stroke) -> None:
    app_client = make_client(tmp_path, low_stroke, viser=True, max_duration_s=600.0)
    with app_client as c:
        view = c.app.state.viser
        view._stop.set()
        g = view.gui
        assert (g.amplitude.max, g.amplitude.value) == (0.03, 0.03)
        assert (g.duration.max, g.duration.value) == (600.0, 240.0)
        assert (g.setpoint.min, g.setpoint.max, g.setpoint.value) == (301.0, 1300.0, 1100.0)
        assert (g.period.min, g.period.max) == (1.0, 600.0)
