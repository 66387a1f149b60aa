"""``furnace-twin run`` on a furnace over OPC UA: an endpoint it cannot use is one line and exit 2; a furnace
lost during the run ends it with status plant_lost, its data written (metrics, time series) and exit 3."""

from __future__ import annotations

import json
import socket

import numpy as np

from twin.config import small_config
from twin.experiments.run import execute_run
from twin.furnace.interface import FurnaceLost
from twin.furnace.simulated import SimulatedFurnace
from twin.runs.loop import ClosedLoop
from twin.runs.record import load_arrays
from twin.scenario import Scenario


def test_run_on_an_unreachable_or_refused_endpoint_exits_2(tmp_path, capsys, monkeypatch) -> None:
    from furnace_twin.cli import main

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        sc = tmp_path / "s.json"
        sc.write_text(json.dumps({"plant": {"kind": "opcua", "endpoint": f"opc.tcp://127.0.0.1:{port}/x/"}}))
        monkeypatch.setenv("FURNACE_TWIN_DATA_DIR", str(tmp_path / "data"))
        assert main(["run", "--scenario", str(sc), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert "connection refused" in err and "Traceback" not in err
    sc.write_text(json.dumps({"plant": {"kind": "opcua", "endpoint": "opc.tcp://192.0.2.1:4840/x/"}}))
    assert main(["run", "--scenario", str(sc), "--out", str(tmp_path / "o")]) == 2
    assert "FURNACE_TWIN_OPCUA_ENDPOINTS" in capsys.readouterr().err


class _LostAt(SimulatedFurnace):
    """A furnace whose link is lost for good at run time ``t_lost``."""

    t_lost = 1.0

    def read(self, t: float):
        if t >= self.t_lost - 1e-9:
            raise FurnaceLost("the link to the furnace was lost and not restored within 2 s (test)")
        return super().read(t)


def test_a_lost_furnace_ends_the_run_with_its_data(tmp_path, small_radiation) -> None:
    cfg = small_config()
    scenario = Scenario.model_validate({"reference": {"setpoint": 600.0, "t_E": 4.0}, "duration": 8.0})
    loop = ClosedLoop(cfg, scenario, small_radiation, furnace=_LostAt.for_scenario(cfg, scenario, small_radiation))
    result = execute_run(loop, tmp_path / "out", figures=False)
    assert result["status"] == "plant_lost" and "not restored" in result["error"]
    data = load_arrays(tmp_path / "out" / "timeseries.npz")
    assert np.allclose(data["t"], np.arange(10) * 0.1)  # every sample before the loss
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["mean_error_steady_max"] is None and metrics["mean_error_transient_max"] is not None
