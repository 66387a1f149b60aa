"""The whole lifecycle through FastAPI's TestClient with the real closed loop (small_config):
start, stream, reference change and oscillation toggle visible in the frames, finish, files,
the .rrd read back by rerun's own CLI.  (Stopping a real run is in test_browser.py, the fake-loop
stop in test_api_contract.py: each real run costs a feedforward solve.)"""

from __future__ import annotations

import io
import json
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import stream_frames, wait_model_ready, wait_status

# 30 s: a change is in force once re-planned, which takes seconds of wall time on a loaded machine; short and
# steep, yet within what the furnace can follow (twin.control.feasibility: warned, not refused)
SCENARIO = {"duration": 30.0, "speed": 3.0, "reference": {"setpoint": 700.0, "t_E": 6.0}, "seed": 3}
REF_AT, NEW_REF = 3.0, {"setpoint": 600.0, "t_E": 3.0}
OSC_AT, NEW_OSC = 5.0, {"enabled": True, "amplitude": 0.03, "period": 2.0}
ABSURD_AT = 8.0


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory, small_cfg):
    data = tmp_path_factory.mktemp("lifecycle")
    # a PUT answers when its re-plan is done (not "pending" after the default 5 s on a loaded machine)
    with TestClient(create_app(Settings(data_dir=data, change_timeout_s=120.0), small_cfg),
                    base_url="http://127.0.0.1") as c:
        wait_model_ready(c)  # the POST's feasibility warnings come with its answer once the model is ready
        r = c.post("/api/runs", json=SCENARIO)
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        changes: dict = {"warnings": r.json()["warnings"]}

        def change(f: dict) -> None:
            if "reference" not in changes and f["t"] >= REF_AT:
                resp = c.put(f"/api/runs/{run_id}/reference", json=NEW_REF)
                changes["reference"] = (resp, time.time())
            if "oscillation" not in changes and f["t"] >= OSC_AT:
                resp = c.put(f"/api/runs/{run_id}/oscillation", json=NEW_OSC)
                changes["oscillation"] = (resp, time.time())
            if "absurd" not in changes and f["t"] >= ABSURD_AT:  # +600 K in 1.5 s: refused, nothing changes
                changes["absurd"] = c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 1250.0, "t_E": 1.5})

        frames = stream_frames(c, run_id, change)
        body = wait_status(c, run_id, {"finished", "error"})
        metrics = c.get(f"/api/runs/{run_id}/metrics")
        npz = c.get(f"/api/runs/{run_id}/timeseries")
        rrd = c.get(f"/api/runs/{run_id}/recording")
        yield {"id": run_id, "frames": frames, "changes": changes, "body": body, "metrics": metrics,
               "npz": npz, "rrd": rrd, "folder": data / "runs" / run_id, "client": c}


def test_frames_follow_the_contract(finished_run, small_cfg) -> None:
    frames = finished_run["frames"]
    assert finished_run["body"]["status"] == "finished", finished_run["body"]["error"]
    s = small_cfg.specimen
    for f in frames:
        assert len(f["field"]) == s.ny and all(len(row) == s.nx for row in f["field"])
        assert len(f["tc"]) == 4 and len(f["tc_hat"]) == 4 and len(f["u"]) == 6 and len(f["u_ff"]) == 6
        assert all(0.0 <= u <= 1.0 + 1e-9 for u in f["u"])  # group powers are fractions of u_max
    ts = [f["t"] for f in frames]
    assert ts == sorted(ts) and ts[-1] == pytest.approx(SCENARIO["duration"])
    # speed 3 x 10 samples per simulated s = 30 samples/s, capped at 20 frames/s per client:
    # 30 s / 3 = 10 s of wall time -> at most ~200 frames, and far more than a handful
    assert 20 <= len(frames) <= 10 * 20 + 2


def _first_frame_after(frames: list[dict], t: float) -> dict:
    return next(f for f in frames if f["t"] > t + 1e-9)


def test_reference_change_visible_in_frames(finished_run) -> None:
    resp, answered = finished_run["changes"]["reference"]
    assert resp.status_code == 200, resp.text
    change = resp.json()
    assert change["status"] == "applied"
    t0 = change["applied_t"]
    frames = finished_run["frames"]
    assert max(f["T_ref"] for f in frames if f["t"] <= t0) <= 700.0 + 1e-6  # old setpoint, still ramping
    # the new reference holds 600 K once its 3 s transition is over (C1 transition, then constant)
    settled = [f["T_ref"] for f in frames if f["t"] >= t0 + NEW_REF["t_E"] + 0.2]
    assert settled and all(abs(T - 600.0) < 0.5 for T in settled)
    # the stream shows the change within a second of the answer (wall clock of the sample)
    assert _first_frame_after(frames, t0)["wall_time"] - answered < 1.0


def test_oscillation_toggle_visible_in_frames(finished_run) -> None:
    resp, answered = finished_run["changes"]["oscillation"]
    assert resp.status_code == 200, resp.text
    t0 = resp.json()["applied_t"]
    frames = finished_run["frames"]
    assert all(f["eta"] == 0.0 for f in frames if f["t"] <= t0)
    late = [abs(f["eta"]) for f in frames if f["t"] > t0 + 1.0]
    # amplitude 0.03 m, period 2 s: over >= 5 s of frames |eta| comes near 0.03 m, never above
    assert 0.02 < max(late) <= 0.03 + 1e-9
    assert _first_frame_after(frames, t0)["wall_time"] - answered < 1.0
    kinds = [(ch["kind"], ch["status"]) for ch in finished_run["body"]["changes"]]
    assert kinds == [("reference", "applied"), ("oscillation", "applied")]  # the absurd one never reached the run


def test_feasibility_warns_at_the_start_and_refuses_an_absurd_change(finished_run) -> None:
    warnings = finished_run["changes"]["warnings"]  # 700 K in 6 s is steeper than full power allows
    assert warnings and "at t = " in warnings[0] and "K short" in warnings[0]
    absurd = finished_run["changes"]["absurd"]
    assert absurd.status_code == 422 and "cannot follow the new reference" in absurd.json()["detail"]


def test_files_and_metrics(finished_run, small_cfg) -> None:
    from twin.runs.metrics import compute_metrics

    assert finished_run["metrics"].status_code == 200
    metrics = finished_run["metrics"].json()
    z = np.load(io.BytesIO(finished_run["npz"].content))
    for key in ("t", "eta", "T_ref", "T_mean_hat", "tc", "tc_hat", "u", "u_ff", "field_hat", "field_true",
                "t_field", "x", "y", "L_s", "W_s", "t_E", "setpoint", "scenario"):
        assert key in z.files, key
    n = len(z["t"])
    assert n == round(SCENARIO["duration"] / small_cfg.sampling.t_s) + 1  # samples 0 .. duration
    assert z["tc"].shape == (n, 4) and z["u"].shape == (n, 6)
    assert z["field_hat"].shape[1:] == (small_cfg.specimen.ny, small_cfg.specimen.nx)
    assert json.loads(str(z["scenario"]))["duration"] == SCENARIO["duration"]
    # metrics.json is recomputable from timeseries.npz (product.md)
    again = compute_metrics({k: z[k] for k in z.files})
    for k, v in again.items():
        if isinstance(v, dict):  # calibration {name: {value, sigma}} of the default (calibrating) estimator
            assert metrics[k] == v, k
        elif np.isnan(v):
            assert metrics[k] is None, k  # a window the run did not reach is null in JSON
        else:
            assert metrics[k] == pytest.approx(v, rel=1e-9), k
    assert json.loads((finished_run["folder"] / "metrics.json").read_text()) == metrics
    # the live changes and the run's events are in the time series (the metric windows follow the reference)
    applied = {ch["kind"]: ch["applied_t"] for ch in finished_run["body"]["changes"]}
    assert [str(k) for k in z["change_kind"]] == ["reference", "oscillation"]
    np.testing.assert_allclose(z["change_t"], [applied["reference"], applied["oscillation"]])
    assert json.loads(str(z["change_json"][0])) == NEW_REF
    texts = [str(e) for e in z["event_text"]]
    assert texts[0].startswith("run started") and texts[1].startswith("feasibility:") and texts[-1] == "run finished"
    assert any(t.startswith("reference change requested at t = ") and t.endswith(": 600 K in 3 s") for t in texts)
    assert any(t.startswith("re-planned (reference changed at t = ") and "to 600 K in 3 s" in t for t in texts)
    assert len(z["event_level"]) == len(texts)  # (a re-plan may still be solving when this short run ends)


def test_recording_opens_with_rerun_cli(finished_run, isolated_home) -> None:
    rrd = finished_run["folder"] / "recording.rrd"
    assert finished_run["rrd"].content == rrd.read_bytes()
    rerun = Path(__file__).resolve().parents[2] / ".venv" / "bin" / "rerun"
    env = {"HOME": str(isolated_home), "XDG_CONFIG_HOME": str(isolated_home / "cfg"),
           "XDG_CACHE_HOME": str(isolated_home / "cache"), "XDG_DATA_HOME": str(isolated_home / "data"),
           "PATH": "/usr/bin:/bin", "RERUN_ANALYTICS": "0"}
    out = subprocess.run([str(rerun), "rrd", "stats", str(rrd)], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    for entity in ("/field/estimated", "/field/true", "/field/fillet", "/field/tc", "/temperature/T_ref",
                   "/temperature/T_mean_hat", "/tc/reading/TC1", "/tc/reading/TC4", "/tc/error/TC4",
                   "/power/u/T1h", "/power/u_ff/T2v", "/eta", "/inhomogeneity/estimated", "/events"):
        assert entity in out.stdout, entity
    verify = subprocess.run([str(rerun), "rrd", "verify", str(rrd)], capture_output=True, text=True, env=env,
                            timeout=120)
    assert verify.returncode == 0, verify.stderr[-2000:]


def test_unreachable_reference_is_refused_before_a_run_starts(tmp_path, small_cfg) -> None:
    """With the real loop factory, POST checks the reference against what the furnace can hold: a 422
    that says why, instead of a run that would end far from its reference."""
    with TestClient(create_app(Settings(data_dir=tmp_path), small_cfg), base_url="http://127.0.0.1") as c:
        wait_model_ready(c)  # during the warm-up a POST is queued and checked later (test_warm_up.py)
        # 350 K is above the initial 300 K, but with the lamps off the warm holders and walls keep the
        # specimen near 480 K (twin.control.feasibility.hold_range): the last point cannot be held
        r = c.post("/api/runs", json={"reference": {"points": [[60.0, 900.0], [120.0, 350.0]]}, "duration": 240.0})
        assert r.status_code == 422, r.text
        detail = r.json()["detail"]
        assert "350 K" in detail and "lamps off" in detail and "t = " in detail, detail
        assert c.get("/api/runs").json() == []
