"""``furnace-twin opcua-check``: every node the twin needs, found or not, with its NodeId, type and access, and
nothing written (issue 24, deliverable 3).  The emulator runs in this process (its own thread), the command in a
subprocess, as an integrator runs it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from opcua_helpers import InProcessEmulator, child_env, endpoint, free_port, small_config_file

from twin.config import small_config
from twin.furnace.emulator.server import FurnaceEmulator
from twin.furnace.opcua.nodes import load_mapping
from twin.furnace.simulated import SimulatedFurnace

CFG = small_config()
GROUPS = [g.name for g in CFG.lamps.groups]
MAPPING = """object = "Plant/Annealer"
[nodes]
TC1 = {node = "nsu=urn:lab:annealer;s=PLC1.TE101", offset = -273.15}
T1h = {node = "Heating/Zone1", scale = 100.0}
Watchdog = "Safety/Heartbeat"
"""


def check(tmp_path, url: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "furnace_twin.cli", "--config", str(small_config_file(tmp_path)),
                           "opcua-check", url, *args], capture_output=True, text=True, timeout=120,
                          env=child_env(FURNACE_TWIN_DATA_DIR=str(tmp_path / "data")), cwd=tmp_path)


@pytest.fixture(scope="module")
def lab_furnace(tmp_path_factory):
    folder = tmp_path_factory.mktemp("check")
    (folder / "lab.toml").write_text(MAPPING)
    port = free_port()
    emulator = FurnaceEmulator(SimulatedFurnace(CFG, radiation=None, tc_noise=0.0), endpoint(port),
                               load_mapping(folder / "lab.toml", GROUPS), eta_max=CFG.oscillation.eta_max, T0=300.0)
    with InProcessEmulator(emulator):
        yield emulator, port, folder / "lab.toml"


def test_every_node_with_its_nodeid_type_and_access_and_nothing_written(lab_furnace, tmp_path) -> None:
    emulator, port, mapping = lab_furnace
    out = check(tmp_path, endpoint(port), "--mapping", str(mapping), "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    nodes = {n["name"]: n for n in result["nodes"]}
    assert set(nodes) == {"TC1", "TC2", "TC3", "TC4", "Eta", "OscillationEnabled", "Amplitude", "Period",
                          "Watchdog", "LampsEnabled", *GROUPS, "LockStep"} and result["ok"]
    tc1 = nodes["TC1"]  # by namespace URI, whatever index the server gave it
    assert tc1["nsu_node_id"] == "nsu=urn:lab:annealer;s=PLC1.TE101" and tc1["data_type"] == "Double"
    assert tc1["access"] == "read" and tc1["source_timestamp"]
    assert 20.0 < tc1["value"] < 80.0  # deg C on the wire, as the mapping says (a plate warming from 300 K)
    assert result["namespaces"][int(tc1["node_id"].split(";")[0][3:])] == "urn:lab:annealer"
    assert (nodes["Watchdog"]["data_type"], nodes["Watchdog"]["access"]) == ("UInt32", "read/write")
    assert nodes["T1h"]["where"].startswith("T1h (Plant/Annealer/Heating/Zone1")
    assert all(n["problem"] is None for n in nodes.values())
    # it wrote nothing: no watchdog (the lamps stay off), no setpoint
    assert emulator.interlock.value is None and not emulator.interlock.lamps_enabled
    assert emulator.space.value("T1h") == 0.0
    table = check(tmp_path, endpoint(port), "--mapping", str(mapping))
    assert table.returncode == 0 and "every node the twin needs is there and usable" in table.stdout
    assert "nsu=urn:lab:annealer;s=PLC1.TE101" in table.stdout


def test_missing_nodes_unreachable_servers_and_bad_mappings(lab_furnace, tmp_path) -> None:
    _, port, mapping = lab_furnace
    wrong = tmp_path / "wrong.toml"
    wrong.write_text(MAPPING.replace("PLC1.TE101", "PLC1.TE999").replace('"Safety/Heartbeat"', '"Safety/Pulse"'))
    out = check(tmp_path, endpoint(port), "--mapping", str(wrong), "--json")
    assert out.returncode == 1, out.stderr
    problems = {n["name"]: n["problem"] for n in json.loads(out.stdout)["nodes"] if n["problem"]}
    assert set(problems) == {"TC1", "Watchdog"}
    assert problems["Watchdog"].startswith("not found: Watchdog (Plant/Annealer/Safety/Pulse")
    default = check(tmp_path, endpoint(port))  # product.md's address space: this server has none
    assert default.returncode == 1 and "has no object Furnace under Objects" in default.stderr
    gone = check(tmp_path, endpoint(free_port()))
    assert gone.returncode == 2 and "connection refused" in gone.stderr and "Traceback" not in gone.stderr
    bad = check(tmp_path, "http://127.0.0.1:1/")
    assert bad.returncode == 2 and "must start with opc.tcp://" in bad.stderr
