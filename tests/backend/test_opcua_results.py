"""The twin's own results over OPC UA (issue 24, deliverable 5): ``Twin/Runs/Current/*`` of the newest run, the
sample's time as source timestamp, read-only for every session, secure by the twin's settings.

The run here is the stand-in loop (the plumbing); ``tests/furnace/test_o6_interop.py`` reads a real run's
results with an independent stack (open62541)."""

from __future__ import annotations

import asyncio
import datetime
import json
import math
import time

import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError

from backend.app import create_app
from backend.core.settings import Settings
from conftest import fake_factory, wait_status
from twin.furnace.opcua.options import OpcUaOptions

NAMES = ("RunId", "Status", "T", "T_ref", "T_mean_hat", "T_sup_hat", "TC4Error", "FieldSigmaMean",
         "LampEfficiency", "Emissivity", "FieldMin", "FieldMax")


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _read_all(url: str) -> dict:
    from asyncua import Client, ua

    async with Client(url, timeout=10) as c:
        idx = await c.get_namespace_index("urn:furnace-twin:results")
        current = await c.nodes.objects.get_child([f"{idx}:Twin", f"{idx}:Runs", f"{idx}:Current"])
        out = {}
        for name in NAMES:
            node = await current.get_child(f"{idx}:{name}")
            out[name] = await node.read_data_value(raise_on_bad_status=False)
        with pytest.raises(ua.uaerrors.BadNotWritable):
            await (await current.get_child(f"{idx}:T_mean_hat")).write_value(ua.Variant(1.0, ua.VariantType.Double))
        with pytest.raises(ua.UaStatusCodeError):  # no session may change the address space
            await current.add_variable(idx, "Injected", 1.0)
        units = await (await current.get_child(f"{idx}:T_mean_hat")).get_child(f"{idx}:EngineeringUnits")
        out["unit"] = (await units.read_value()).DisplayName.Text
        return out


def test_the_newest_run_is_served_read_only_with_the_samples_time(tmp_path, small_cfg) -> None:
    port = _free_port()
    url = f"opc.tcp://127.0.0.1:{port}/furnace-twin/results/"
    settings = Settings(data_dir=tmp_path, opcua_results_endpoint=url)
    app = create_app(settings, small_cfg, loop_factory=fake_factory(step_cost_s=0.002))
    with TestClient(app, base_url="http://127.0.0.1") as c:
        before = datetime.datetime.now(datetime.UTC)
        run_id = c.post("/api/runs", json={"duration": 8.0, "speed": 2.0}).json()["id"]
        wait_status(c, run_id, {"running"})
        while (c.get(f"/api/runs/{run_id}").json()["latest"] or {}).get("t", 0.0) < 0.5:
            time.sleep(0.05)
        live = asyncio.run(_read_all(url))
        body = wait_status(c, run_id, {"finished"})
        time.sleep(0.5)  # the server looks for the newest sample ten times a second
        done = asyncio.run(_read_all(url))
    assert live["RunId"].Value.Value == run_id and live["Status"].Value.Value == "running"
    assert live["unit"] == "K"
    stamp = live["T_mean_hat"].SourceTimestamp.replace(tzinfo=datetime.UTC)
    assert before <= stamp <= datetime.datetime.now(datetime.UTC)  # the sample's time, not the server's
    assert done["Status"].Value.Value == "finished" and done["RunId"].Value.Value == run_id
    frame = json.loads(app.state.manager.last_frame(run_id))  # the last sample, as the stream sent it
    stamped = done["T_mean_hat"].SourceTimestamp.replace(tzinfo=datetime.UTC).timestamp()
    assert stamped == pytest.approx(frame["wall_time"], abs=1e-5)  # when the twin computed it
    last = body["latest"]
    assert done["T"].Value.Value == pytest.approx(last["t"])
    assert done["T_mean_hat"].Value.Value == pytest.approx(last["T_mean_hat"])
    assert done["T_ref"].Value.Value == pytest.approx(last["T_ref"])
    assert done["FieldMin"].Value.Value <= last["T_mean_hat"] <= done["FieldMax"].Value.Value
    # what the stand-in does not estimate is said to be missing, not 0
    for name in ("FieldSigmaMean", "LampEfficiency", "Emissivity"):
        assert done[name].StatusCode.name == "BadNoData" and done[name].Value.Value is None, name
    assert math.isfinite(done["TC4Error"].Value.Value)


def test_without_security_only_on_loopback() -> None:
    with pytest.raises(ValidationError, match="needs FURNACE_TWIN_OPCUA_SECURITY=sign-encrypt"):
        Settings(opcua_results_endpoint="opc.tcp://10.0.0.5:4841/furnace-twin/results/")
    with pytest.raises(ValidationError, match="must start with opc.tcp://"):
        Settings(opcua_results_endpoint="http://127.0.0.1:4841/")
    ok = Settings(opcua_results_endpoint="opc.tcp://10.0.0.5:4841/x/", opcua=OpcUaOptions(security="sign-encrypt"))
    assert ok.opcua_results_endpoint.startswith("opc.tcp://10.0.0.5")
