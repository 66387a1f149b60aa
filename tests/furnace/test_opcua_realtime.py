"""Hardware in the loop on loopback, in real time: ``furnace-twin emulate`` in a subprocess, the twin through
its REST API (or ``furnace-twin run``) on the small furnace.

* a closed-loop run over OPC UA in real time runs the in-process loop, sample for sample, until timing
  disturbs it (a late sample, the twin behind the furnace's clock, the furnace holding an older command or
  switching its lamps off), reports no truth and stores what a real furnace gives; undisturbed, its metrics
  are the in-process ones (the exact comparison itself is ``test_opcua_lockstep.py``);
* the emulator killed mid-run: the run ends ``plant_lost`` and its data stays readable;
* the twin killed mid-run: the emulator's lamps go off within 1.5 s (its watchdog interlock).

All real-time tests live in this file (``--dist loadfile`` keeps them on one worker, one after another)
and carry the ``realtime`` mark; their timeouts are generous for a loaded 2-core machine, their pass
criteria are not timing figures.

Why the real-time comparison is not a tolerance on the metric: a CI run gave 1.301 % steady mean error over
OPC UA against 1.587 % in process with no late sample.  Such a run is what a stalled twin gives: a run whose
loop thread stalled 1.4 s at t = 5 s (injected) counted no late sample (the samples waited in the buffer and
were taken complete), the emulator's watchdog switched the lamps off for the last 0.4 s of the stall, and
the run ended at 1.176 %; in process, lamps off after a stall of 1.2-1.3 s in the heat-up give 1.22-1.40 %
(and a one-sample command delay, the guess of commit 4ebefe4, 1.603 %: the other way).  Such runs now report
it (the twin fell behind, the furnace switched its lamps off), and this test compares the loop up to the
first disturbance, exactly.
"""

from __future__ import annotations

import io
import json
import subprocess
import sys
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from opcua_helpers import Peek, child_env, emulator_process, run_over_opcua, small_config_file, twin_app, wait_status

from twin.config import small_config
from twin.runs.loop import ClosedLoop
from twin.scenario import Scenario

pytestmark = pytest.mark.realtime

CFG = small_config()
# 700 K in t_E = 12 s, a 24 s run (steady window 18..24 s): the lamps heat at full power, then hold
BASE = {"reference": {"setpoint": 700.0, "t_E": 12.0}, "duration": 24.0, "seed": 4, "tc_noise": 1.0}
#: 0.01 % of the setpoint, for a run that nothing disturbed: it ran the in-process loop (the transport is exact,
#: test_opcua_lockstep.py), so only rounding may differ
UNDISTURBED = 1e-4


def wait_running_for(c: TestClient, run_id: str, t: float, timeout: float) -> dict:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        body = c.get(f"/api/runs/{run_id}").json()
        if body["status"] not in ("queued", "starting", "running"):
            raise AssertionError(f"run ended early: {body['status']} {body.get('error')}")
        if body.get("latest") and body["latest"]["t"] >= t:
            return body
        time.sleep(0.1)
    raise AssertionError(f"run {run_id} did not reach t = {t} s")


def app(tmp_path, **opcua) -> TestClient:
    return twin_app(tmp_path, CFG, **opcua)


def first_disturbance(npz, applied: list[int]) -> tuple[int, str]:
    """The first sample from which the run over OPC UA may differ from the in-process one, and why: a sample with
    a missing reading; the twin's first sample repeated (its first command reached the furnace a period late,
    so the specimen was loaded a sample later); the furnace computing sample k + 1 with another command than
    the twin's for sample k (watchdog k + 1; -1: lamps off)."""
    n = len(npz["t"])
    late = np.flatnonzero(np.any(npz["tc_status"] == 2, axis=1))
    candidates = [(int(late[0]), "a late sample")] if late.size else []
    if n > 1 and np.array_equal(npz["tc"][1], npz["tc"][0]):
        candidates.append((1, "the specimen was loaded a sample late"))
    for k, w in enumerate(applied[: n - 1]):
        if w != k + 1:
            candidates.append((k + 1, f"sample {k + 1} computed with command {w}, not {k + 1}"))
            break
    return min(candidates, default=(n, "nothing"))


def test_closed_loop_over_opcua_runs_the_in_process_loop_until_timing_disturbs_it(tmp_path, small_radiation) -> None:
    in_process = ClosedLoop(CFG, Scenario.model_validate(BASE), small_radiation)
    list(in_process.run())
    reference, ref = in_process.metrics(), in_process.timeseries()

    # the emulated furnace: same seed and TC noise, its specimen at 300 K until the twin starts (as in process)
    metrics, npz, stats = run_over_opcua(tmp_path, CFG, BASE, "--load-on-first-client")
    events = [str(e) for e in npz["event_text"]]

    j0, why = first_disturbance(npz, stats["applied"])
    steady, steady_ref = metrics["mean_error_steady_max"], reference["mean_error_steady_max"]
    print(f"steady mean error over OPC UA {100 * steady:.3f} %, in process {100 * steady_ref:.3f} % of the setpoint; "
          f"{metrics['late_samples']} late samples; the in-process loop up to sample {j0} ({why}); interlock trips "
          f"{stats['interlock_trips']}")  # shown with -rP
    # up to the first disturbance the furnace ran the twin's loop: the same readings and commands as in process
    assert np.array_equal(npz["tc"][:j0], ref["tc"][:j0], equal_nan=True)
    assert np.max(np.abs(npz["u"][:j0] - ref["u"][:j0]), initial=0.0) == 0.0
    if j0 == len(npz["t"]):  # nothing disturbed the run: its figures are the in-process ones
        assert abs(steady - steady_ref) <= UNDISTURBED, (steady, steady_ref)
    # the furnace computed a sample of the run with its lamps off (its interlock tripped while the twin drove it):
    # the twin says so.  Not stats["interlock_trips"]: that also counts the trip once the finished twin stopped
    # writing and the emulator outlived it by more than the watchdog's 1 s (a CI run on a loaded machine)
    off = [k + 1 for k, w in enumerate(stats["applied"][: len(npz["t"]) - 1]) if w == -1]
    if off:
        assert any("switched its lamps off" in e for e in events), (off, events)
    for key in ("true_inhomogeneity_steady", "true_mean_error_steady_max", "field_estimation_error_steady_max"):
        assert metrics[key] is None, key  # a furnace over OPC UA has no truth
    assert "field_true" not in npz.files
    t = npz["t"]
    assert len(t) == 241 and np.allclose(np.diff(t), CFG.sampling.t_s)
    assert metrics["late_samples"] == int(np.any(npz["tc_status"] == 2, axis=1).sum())
    assert metrics["late_samples"] <= 24, "more than 10 % of the samples came late on loopback"
    # the readings are the emulator's: they rose with the lamps, and the estimate follows them
    assert np.nanmean(npz["tc"][-10:, :3]) > 650.0
    assert np.nanmax(np.abs(npz["tc"][-50:, :3] - npz["tc_hat"][-50:, :3])) < 20.0


def test_emulator_killed_mid_run_ends_plant_lost_with_its_data(tmp_path) -> None:
    with emulator_process(tmp_path) as emu, app(tmp_path, reconnect_s=2.0) as c:
        r = c.post("/api/runs", json={**BASE, "duration": 120.0, "plant": {"kind": "opcua", "endpoint": emu.url}})
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        wait_running_for(c, run_id, 2.0, timeout=120)
        emu.kill()
        t_kill = time.monotonic()
        body = wait_status(c, run_id, {"finished", "error", "plant_lost", "stopped"}, timeout=60)
        lost_after = time.monotonic() - t_kill
        print(f"run ended {body['status']} {lost_after:.1f} s after the emulator was killed")  # shown with -rP
        assert body["status"] == "plant_lost", body
        assert "not restored within 2 s" in body["error"]
        assert 2.0 <= lost_after < 30.0
        npz = np.load(io.BytesIO(c.get(f"/api/runs/{run_id}/timeseries").content))
        t = npz["t"]
        assert len(t) >= 20 and t[-1] >= 2.0
        assert (npz["tc_status"][-5:] == 3).all()  # its last samples: the link was down ("unlinked"), nothing came
        metrics = c.get(f"/api/runs/{run_id}/metrics")
        assert metrics.status_code == 200 and metrics.json()["status"] == "plant_lost"  # the ending, not only a code
        assert metrics.json()["status_reason"] == body["status_reason"]
        assert body["status_reason"].startswith(body["error"]) and "blind once" in body["status_reason"], body
        assert c.get(f"/api/runs/{run_id}/recording").status_code == 200
        events = dict(zip((str(e) for e in npz["event_text"]), (str(v) for v in npz["event_level"]), strict=True))
        lost = [e for e in events if "link to the furnace lost" in e]
        assert lost and events[lost[0]] == "warn", events  # the loop's report of the lost link: a warning
        end = [e for e in events if e.startswith("run lost its furnace")]
        assert end and events[end[0]] == "error", events  # the end of the run: an error, as a failed run's


def test_twin_killed_mid_run_the_emulator_turns_the_lamps_off(tmp_path) -> None:
    with emulator_process(tmp_path) as emu:
        scenario = tmp_path / "twin.json"
        scenario.write_text(json.dumps({**BASE, "duration": 300.0, "plant": {"kind": "opcua", "endpoint": emu.url}}))
        twin = subprocess.Popen(
            [sys.executable, "-m", "furnace_twin.cli", "--config", str(small_config_file(tmp_path)), "run",
             "--scenario", str(scenario), "--out", str(tmp_path / "out")],
            stdout=subprocess.DEVNULL, stderr=open(tmp_path / "twin.log", "wb"),
            env=child_env(FURNACE_TWIN_DATA_DIR=str(tmp_path / "twin-data")), cwd=tmp_path)
        peek = Peek(emu.url)
        try:
            end = time.monotonic() + 120
            while not (peek.value("LampsEnabled") and peek.value("T1h") > 0.0):
                assert twin.poll() is None, (tmp_path / "twin.log").read_text()
                assert time.monotonic() < end, "the twin never drove the lamps"
                time.sleep(0.05)
            time.sleep(1.0)
            assert peek.value("LampsEnabled")
            twin.kill()
            t_kill = time.monotonic()
            while peek.value("LampsEnabled") and time.monotonic() - t_kill < 10:
                time.sleep(0.01)
            off_after = time.monotonic() - t_kill
        finally:
            peek.close()
            if twin.poll() is None:
                twin.kill()
            twin.wait(10)
        print(f"lamps off {off_after:.2f} s after the twin was killed")  # shown with -rP
        assert off_after <= 1.5, f"lamps still on {off_after:.2f} s after the twin died"
    assert "interlock trip 1" in emu.log.read_text()  # the trip is logged
