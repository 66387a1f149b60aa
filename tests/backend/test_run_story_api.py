"""A run described by what happened (issue 27 item 5) in ``GET /api/runs`` and the report's file name, and the
files a run has in the list (item 10: an interrupted run offered links that answered a raw 404); with the fast
stand-in loop (conftest.FakeLoop)."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import fake_factory, stream_frames, wait_status


def test_the_list_tells_what_happened_and_which_files_exist(tmp_path: Path, small_cfg) -> None:
    s = Settings(data_dir=tmp_path / "data")
    with TestClient(create_app(s, small_cfg, loop_factory=fake_factory()), base_url="http://127.0.0.1") as c:
        r = c.post("/api/runs", json={"duration": 5.0, "speed": 5.0, "reference": {"setpoint": 900.0, "t_E": 3.0},
                                      "oscillation": {"enabled": False, "amplitude": 0.03, "period": 2.0}})
        run_id = r.json()["id"]
        done: set[str] = set()

        def change(f: dict) -> None:
            if "reference" not in done and f["t"] >= 1.0:
                assert c.put(f"/api/runs/{run_id}/reference", json={"setpoint": 1000.0, "t_E": 1.5}).status_code == 200
                done.add("reference")
            if "oscillation" not in done and f["t"] >= 2.0:
                assert c.put(f"/api/runs/{run_id}/oscillation",
                             json={"enabled": True, "amplitude": 0.04, "period": 1.0}).status_code == 200
                done.add("oscillation")

        stream_frames(c, run_id, change)
        body = wait_status(c, run_id, {"finished"})
        t_ref, t_osc = (next(ch["applied_t"] for ch in body["changes"] if ch["kind"] == k)
                        for k in ("reference", "oscillation"))
        listed = next(x for x in c.get("/api/runs").json() if x["id"] == run_id)
        # as it ended, not as it started ("900 K / 3 s, osc off")
        assert listed["story"] == {
            "reference": f"1000 K / 1.5 s (changed at {t_ref:.1f} s)",
            "oscillation": f"on from {t_osc:.1f} s (40 mm / 1 s)",
            "auto_label": f"osc 40 mm / 1 s from {t_osc:.1f} s",
            "text": f"1000 K / 1.5 s (changed at {t_ref:.1f} s) · osc on from {t_osc:.1f} s (40 mm / 1 s)"}
        assert body["story"] == listed["story"]
        assert listed["files"] == {"recording": True, "timeseries": True, "metrics": True}
        # the report is named by the (automatic) label, then the id
        rep = c.get(f"/api/runs/{run_id}/report.png")
        assert rep.status_code == 200
        assert f'filename="osc-40-mm-1-s-from-{t_osc:.1f}-s-{run_id}.png"' in rep.headers["content-disposition"]
        # a run whose series is gone (as an interrupted run before its first save): the list says so
        (s.runs_dir / run_id / "timeseries.npz").unlink()
        listed = next(x for x in c.get("/api/runs").json() if x["id"] == run_id)
        assert listed["files"]["timeseries"] is False and listed["files"]["recording"] is True
