"""POST /api/runs with a furnace over OPC UA: an endpoint the server may not connect to, or cannot reach, is a
422 with a message; a furnace is driven by one run at a time (409); OPC UA runs are real time (422 otherwise).
(The runs themselves, in real time against the emulator, are in tests/furnace/test_opcua_realtime.py.)"""

from __future__ import annotations

import socket

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import fake_factory, wait_status
from twin.furnace.opcua.options import OpcUaOptions


def closed_port() -> int:
    with socket.socket() as s:  # bound, never listening: connections are refused
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def opcua(endpoint: str, **extra) -> dict:
    return {"reference": {"setpoint": 700.0, "t_E": 10.0}, "duration": 20.0,
            "plant": {"kind": "opcua", "endpoint": endpoint}, **extra}


@pytest.fixture(scope="module")
def real_factory_client(tmp_path_factory, small_cfg):
    settings = Settings(data_dir=tmp_path_factory.mktemp("plant"), opcua=OpcUaOptions(connect_timeout_s=3.0))
    with TestClient(create_app(settings, small_cfg), base_url="http://127.0.0.1") as c:
        yield c


def test_an_endpoint_not_allowed_is_a_422_naming_the_setting(real_factory_client) -> None:
    r = real_factory_client.post("/api/runs", json=opcua("opc.tcp://10.1.2.3:4840/furnace-twin/"))
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert "plant.endpoint" in detail and "FURNACE_TWIN_OPCUA_ENDPOINTS" in detail and "10.1.2.3" in detail
    assert real_factory_client.get("/api/runs").json() == []  # nothing was started


def test_an_unreachable_endpoint_is_a_422_saying_so(real_factory_client) -> None:
    port = closed_port()
    r = real_factory_client.post("/api/runs", json=opcua(f"opc.tcp://127.0.0.1:{port}/furnace-twin/"))
    assert r.status_code == 422
    assert f"cannot reach opc.tcp://127.0.0.1:{port}/furnace-twin/: connection refused" in r.json()["detail"]


def test_opcua_runs_are_real_time_only(real_factory_client) -> None:
    r = real_factory_client.post("/api/runs", json=opcua("opc.tcp://127.0.0.1:4840/furnace-twin/", speed=10.0))
    assert r.status_code == 422 and "speed must be 1" in r.text
    r = real_factory_client.post("/api/runs", json=opcua("ftp://127.0.0.1/"))
    assert r.status_code == 422 and "opc.tcp://" in r.text


def test_the_allow_list_comes_from_the_environment(tmp_path, small_cfg, monkeypatch) -> None:
    monkeypatch.setenv("FURNACE_TWIN_OPCUA_ENDPOINTS", "10.1.2.0/24:4840")
    monkeypatch.setenv("FURNACE_TWIN_OPCUA_CONNECT_TIMEOUT_S", "1.0")
    with TestClient(create_app(Settings(data_dir=tmp_path), small_cfg), base_url="http://127.0.0.1") as c:
        refused = c.post("/api/runs", json=opcua("opc.tcp://127.0.0.1:4840/furnace-twin/"))
        assert refused.status_code == 422 and "10.1.2.0/24:4840" in refused.json()["detail"]  # loopback no longer
        allowed = c.post("/api/runs", json=opcua("opc.tcp://10.1.2.3:4840/furnace-twin/"))
        # allowed, so it was tried: nothing answers there
        assert allowed.status_code == 422 and "allowed" not in allowed.json()["detail"]
        assert "10.1.2.3" in allowed.json()["detail"]


def test_one_run_per_furnace(tmp_path, small_cfg) -> None:
    with TestClient(create_app(Settings(data_dir=tmp_path), small_cfg, loop_factory=fake_factory()),
                    base_url="http://127.0.0.1") as c:
        first = c.post("/api/runs", json=opcua("opc.tcp://127.0.0.1:4840/furnace-twin/"))
        assert first.status_code == 201, first.text
        second = c.post("/api/runs", json=opcua("opc.tcp://127.0.0.1:4840/furnace-twin/"))
        assert second.status_code == 409 and first.json()["id"] in second.json()["detail"]
        other = c.post("/api/runs", json=opcua("opc.tcp://127.0.0.1:4841/furnace-twin/"))
        assert other.status_code == 201  # another furnace
        for r in (first, other):
            c.post(f"/api/runs/{r.json()['id']}/stop")
            wait_status(c, r.json()["id"], {"stopped", "finished"})
