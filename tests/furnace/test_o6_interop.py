"""Interoperability with an OPC UA stack this project did not write: o6 (open62541) as a client of the emulator
and of the twin's results server, and as a third-party furnace server the twin drives (issue 24, deliverable 6).

The o6 peers run as scripts of their own (``tests/furnace/o6_peers``): importing o6 starts a timer that ends the
process ten minutes later, so the test process never imports it (``test_no_o6_in_this_process``), and each peer
lives well under a minute or two.

* o6 as a client of ``furnace-twin emulate``: product.md's address space by browse name, Double TCs with source
  timestamps, a clamped setpoint answered ``GoodClamped``, a read-only node ``BadNotWritable``, the watchdog
  interlock (lamps on while fed, off after a second of silence), 10 Hz data changes.
* o6 as the furnace: its own namespace (``urn:lab:annealer``), string NodeIds found through ``nsu=`` entries of
  a mapping file, Float TCs in deg C, setpoints in percent, a UInt16 heartbeat, a lumped thermal model.  The twin
  drives it in real time through the dashboard's API while an o6 client reads the twin's results server; the
  furnace's server is killed mid-run and restarted with its namespace at another index (as a reconfigured
  server would), and later frozen (SIGSTOP) with its link up.  Judged as the issue says: the readings are used
  again within 5 s of the link's return (here: at the first sample with readings), the run finishes and says it
  was blind, when, and why.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from opcua_helpers import InProcessEmulator, endpoint, free_port, wait_status

from backend.app import create_app
from backend.core.settings import Settings
from twin.config import small_config
from twin.furnace.emulator.server import FurnaceEmulator
from twin.furnace.opcua.nodes import NodeMap
from twin.furnace.opcua.options import OpcUaOptions
from twin.furnace.simulated import SimulatedFurnace

pytestmark = pytest.mark.realtime

PEERS = Path(__file__).parent / "o6_peers"
CFG = small_config()
LAB_MAPPING = """object = "Plant/Annealer"
namespace = "urn:lab:annealer"
[nodes]
TC1 = {node = "nsu=urn:lab:annealer;s=PLC1.TE101", offset = -273.15}
TC2 = {node = "nsu=urn:lab:annealer;s=PLC1.TE102", offset = -273.15}
TC3 = {node = "nsu=urn:lab:annealer;s=PLC1.TE103", offset = -273.15}
TC4 = {node = "nsu=urn:lab:annealer;s=PLC1.TE104", offset = -273.15}
T1h = {node = "nsu=urn:lab:annealer;s=PLC1.Zone1", scale = 100.0}
T2h = {node = "nsu=urn:lab:annealer;s=PLC1.Zone2", scale = 100.0}
T3h = {node = "nsu=urn:lab:annealer;s=PLC1.Zone3", scale = 100.0}
T4h = {node = "nsu=urn:lab:annealer;s=PLC1.Zone4", scale = 100.0}
T1v = {node = "nsu=urn:lab:annealer;s=PLC1.Zone5", scale = 100.0}
T2v = {node = "nsu=urn:lab:annealer;s=PLC1.Zone6", scale = 100.0}
Watchdog = "nsu=urn:lab:annealer;s=PLC1.Heartbeat"
LampsEnabled = "nsu=urn:lab:annealer;s=PLC1.LampsOn"
OscillationEnabled = "Drive/On"
Amplitude = {node = "Drive/Stroke", scale = 1000.0}
Period = "Drive/Cycle"
Eta = {node = "Drive/Pos", scale = 1000.0}
"""


def o6_client(*args: str, timeout: float = 120.0) -> dict:
    out = subprocess.run([sys.executable, str(PEERS / "client.py"), *args], capture_output=True, text=True,
                         timeout=timeout, cwd=PEERS)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("RESULT ")]
    assert out.returncode == 0 and lines, out.stdout[-3000:] + out.stderr[-3000:]
    return json.loads(lines[-1][len("RESULT "):])


@contextlib.contextmanager
def o6_furnace(port: int, state: Path, spare: int = 0) -> Iterator[tuple[subprocess.Popen[bytes], dict]]:
    """The third-party furnace (o6_peers/furnace.py) on ``port``, until the block ends (killed by its pid).  Its
    output goes to a file: a pipe nobody reads would fill and stop it."""
    log = state.with_name(f"furnace-{port}-{spare}.log")
    with open(log, "wb") as out:
        proc = subprocess.Popen([sys.executable, str(PEERS / "furnace.py"), "--port", str(port), "--state",
                                 str(state), "--spare-namespaces", str(spare), "--seconds", "150"], cwd=PEERS,
                                stdout=out, stderr=subprocess.STDOUT)
    try:
        end = time.monotonic() + 60
        while not (ready := [ln for ln in log.read_text(errors="replace").splitlines() if ln.startswith("READY ")]):
            assert proc.poll() is None, f"the o6 furnace exited:\n{log.read_text(errors='replace')[-3000:]}"
            assert time.monotonic() < end, "the o6 furnace did not start"
            time.sleep(0.05)
        yield proc, json.loads(ready[0][len("READY "):])
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)


def test_o6_client_sees_the_emulator_as_product_md_says(tmp_path) -> None:
    port = free_port()
    emulator = FurnaceEmulator(SimulatedFurnace(CFG, radiation=None, tc_noise=0.0), endpoint(port),
                               NodeMap.default([g.name for g in CFG.lamps.groups]), eta_max=CFG.oscillation.eta_max,
                               T0=300.0)
    with InProcessEmulator(emulator):
        seen = o6_client("emulator", endpoint(port))
    for tc, r in seen["tcs"].items():
        assert (r["type"], r["status"], r["source_timestamp"]) == ("float64", "GOOD", True), tc
        assert 290.0 < r["value"] < 400.0, tc
    assert (seen["clamped"], seen["T1h_after"], seen["in_range"]) == ("GOOD_CLAMPED", 1.0, "GOOD")
    assert seen["read_only"] == "BAD_NOT_WRITABLE" and seen["lock_step"] is False
    assert seen["watchdog_type"] == "uint32"
    assert (seen["lamps_before"], seen["lamps_fed"], seen["lamps_after_silence"]) == (False, True, False)
    assert seen["tc1_changes"] >= 10  # a new sample every 0.1 s for 1.5 s, each a data change with its stamp


def _event_times(npz) -> list[tuple[float, str]]:
    return [(float(t), str(e)) for t, e in zip(npz["event_t"], npz["event_text"], strict=True)]


#: the furnace's server is killed at this run time; before it, nothing the test does disturbs the run
KILL_AT = 10.0
#: run time (s) at which the test freezes the restarted furnace for 2 s
FREEZE_AT = 24.0


def _timing_disturbed_before_the_outages(events: list[tuple[float, str]]) -> list[str]:
    """What says the machine, not the test, disturbed the real-time run: late samples or a TC dropout before
    :data:`KILL_AT` (on a quiet machine there are none; in CI with a busy neighbour on the other core the o6
    furnace's first readings came a second late and its restart's readings 2.6 s late), or a second loss of the
    link before the freeze, which the test does not cause (in a full suite under load the restarted furnace did
    not answer a request in 10 s; meanwhile TC3 and TC4, whose subscription was not yet made again, counted as
    dropouts)."""
    lost = [e for t, e in events if t < FREEZE_AT and e.startswith("link to the furnace lost")]
    return [e for t, e in events if t < KILL_AT and ("late" in e or "dropout" in e)] + lost[1:]


def _drive_through_restart(tmp_path: Path) -> tuple[dict, list[tuple[float, str]], dict, dict, dict, Any, str]:
    """One run of the third-party furnace scenario: (final status, events, the first and second furnace's
    namespaces, what the o6 client read of the twin, the timeseries, the run id)."""
    tmp_path.mkdir()
    port, results_port = free_port(), free_port()
    state, mapping = tmp_path / "furnace-state.json", tmp_path / "lab.toml"
    mapping.write_text(LAB_MAPPING)
    results = f"opc.tcp://127.0.0.1:{results_port}/furnace-twin/results/"
    scenario = {"reference": {"setpoint": 600.0, "t_E": 10.0}, "duration": 34.0, "seed": 1,
                "plant": {"kind": "opcua", "endpoint": f"opc.tcp://127.0.0.1:{port}/"}}
    settings = Settings(data_dir=tmp_path / "data", flush_interval_s=0.5, opcua_results_endpoint=results,
                        opcua=OpcUaOptions(reconnect_s=15.0, connect_timeout_s=10.0, mapping=mapping))
    with o6_furnace(port, state) as (furnace, first), \
            TestClient(create_app(settings, CFG), base_url="http://127.0.0.1") as c:
        r = c.post("/api/runs", json=scenario)
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]

        def at(t: float) -> dict:
            while True:
                body = c.get(f"/api/runs/{run_id}").json()
                assert body["status"] in ("queued", "starting", "running", "degraded"), body
                if (body.get("latest") or {}).get("t", 0.0) >= t:
                    return body
                time.sleep(0.05)

        at(6.0)
        served = o6_client("results", results, "--seconds", "1.5")  # an independent SCADA reads the twin
        at(KILL_AT)
        furnace.kill()  # the furnace's OPC UA server dies; the furnace cools with its lamps off
        furnace.wait(10)
        time.sleep(2.0)
        with o6_furnace(port, state, spare=2) as (furnace2, second):  # back, its namespace at another index
            at(FREEZE_AT)
            furnace2.send_signal(signal.SIGSTOP)  # then frozen 2 s: the link stays up, no readings come
            time.sleep(2.0)
            furnace2.send_signal(signal.SIGCONT)
            body = wait_status(c, run_id, {"finished", "degraded", "error", "plant_lost"}, timeout=120)
            while body["ended_at"] is None:  # degraded is also the live status while blind: until it ended
                time.sleep(0.1)
                body = c.get(f"/api/runs/{run_id}").json()
        npz = np.load(io.BytesIO(c.get(f"/api/runs/{run_id}/timeseries").content))
    return body, _event_times(npz), first, second, served, npz, run_id


def test_the_twin_drives_a_third_party_furnace_through_a_restart_and_serves_its_results(tmp_path) -> None:
    """Judged on a run whose timing only the test's outages disturbed: a run the machine disturbed before them
    (see :func:`_timing_disturbed_before_the_outages`) is said in the log and run once more."""
    for attempt in (1, 2):
        body, events, first, second, served, npz, run_id = _drive_through_restart(tmp_path / f"attempt{attempt}")
        disturbed = _timing_disturbed_before_the_outages(events)
        if not disturbed or attempt == 2:
            break
        logging.getLogger(__name__).warning("the machine disturbed the real-time run before its outages (%s); "
                                            "once more", disturbed[:3])
    texts = [e for _, e in events]
    assert body["status"] == "finished", (body, texts)
    assert first["namespace_index"] != second["namespace_index"]  # found again by URI (nsu=), not by number
    # the restart: the link returns, and the readings are used again at once (the issue: within 5 s)
    restored = next(t for t, e in events if e.startswith("link to the furnace restored"))
    used_again = [t for t, e in events if e.startswith("thermocouple readings used again")]
    assert used_again and 0.0 <= used_again[0] - restored <= 5.0, texts
    assert used_again[0] - restored <= 0.5, texts  # in fact: the first sample after it
    # the freeze: 2 s without readings on a live link, used again with the first sample that comes
    frozen = [t for t, e in events if e.startswith("blind since") and t > used_again[0]]
    assert frozen and len(used_again) == 2, texts
    back = [t for t, e in events if e.startswith("samples on time again") and t > frozen[0]]
    assert back and abs(used_again[1] - back[0]) <= 0.3, texts
    # the run says so when it ends: blind twice, when, and why
    reason = body["status_reason"]
    assert reason.startswith("blind 2 times") and "no readings came from the furnace" in reason, reason
    dropouts = [e for e in texts if "dropout" in e and e.startswith("fault detected")]
    if not disturbed:
        assert not dropouts, dropouts  # an outage: no TC fault
    else:  # both runs disturbed by the machine (a CI run: a second link loss, then TC3's and TC4's subscription
        # delivered seconds after TC1's; they are "unlinked" for connect_timeout_s now, not dropouts, but a server
        # slower than that still makes them so): every TC of the estimate counted so must be used again once its
        # readings return
        logging.getLogger(__name__).warning("judged on a run the machine disturbed: %s", disturbed[:3])
        for i in ("TC1", "TC2", "TC3"):
            if any(e.startswith(f"fault detected: {i} gives no reading") for e in dropouts):
                assert any(e.startswith(f"fault detected: {i} agrees with the estimate again") for e in texts), texts
    # the readings are the furnace's after both outages, and the estimate follows them
    last = npz["t"] > npz["t"][-1] - 3.0
    assert np.isfinite(npz["tc"][last, :3]).mean() > 0.8  # (a loaded machine may lose a sample or two)
    assert np.nanmax(np.abs(npz["tc"][last, :3] - npz["tc_hat"][last, :3])) < 10.0
    # what the independent client read of the twin: this run, live, typed, stamped, read-only
    cur = served["first"]
    assert cur["RunId"]["value"] == run_id and cur["Status"]["value"] in ("running", "degraded")
    assert cur["T_mean_hat"]["type"] == "float64" and cur["T_mean_hat"]["source_timestamp"]
    assert 300.0 < cur["T_mean_hat"]["value"] < 700.0 and cur["LampEfficiency"]["status"] in ("GOOD", "BAD_NO_DATA")
    assert served["write"] == "BAD_NOT_WRITABLE"
    ts = served["t_updates"]
    assert len(ts) >= 5 and all(b > a for a, b in zip(ts, ts[1:], strict=False)), ts  # live, in order


def test_no_o6_in_this_process() -> None:
    """o6 ends the process that imports it after ten minutes: the suite's own processes must never."""
    assert "o6" not in sys.modules and not any(re.match(r"o6\.", m) for m in sys.modules)
