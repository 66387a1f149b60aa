"""``/api/studies``: 201 and a real study on a 2-worker LocalCluster with its results served; bad studies
are 422 with the reason; 404 / 409 / 401; a study going at shutdown is interrupted and resumes."""

from __future__ import annotations

import io
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from conftest import FakeStudyRunner

TOKEN = "studies-token-0123456789"
BASE = {"duration": 12.0, "reference": {"setpoint": 900.0, "t_E": 6.0}}


def make_client(tmp_path: Path, cfg, runner=None, **settings) -> TestClient:
    s = Settings(data_dir=tmp_path / "data", **settings)
    return TestClient(create_app(s, cfg, study_runner=runner), base_url="http://127.0.0.1")


def wait_study(c: TestClient, study_id: str, statuses: set[str], timeout: float = 180.0) -> dict:
    end = time.monotonic() + timeout
    body: dict = {}
    while time.monotonic() < end:
        body = c.get(f"/api/studies/{study_id}").json()
        if body["status"] in statuses:
            return body
        time.sleep(0.1)
    raise AssertionError(f"study {study_id} never reached {statuses}: {body.get('status')} {body.get('error')}")


def test_a_posted_study_runs_on_dask_and_serves_its_results(tmp_path, small_cfg, radiation_cache) -> None:
    with make_client(tmp_path, small_cfg, study_workers=2) as c:
        r = c.post("/api/studies", json={"name": "api", "base": BASE, "grid": {"tc_noise": [0.5, 1.0]}})
        assert r.status_code == 201, r.text
        created = r.json()
        assert created["status"] in ("queued", "running") and created["total"] == 2
        study_id = created["id"]
        assert [s["id"] for s in c.get("/api/studies").json()] == [study_id]
        body = wait_study(c, study_id, {"finished", "error"})
        assert body["status"] == "finished", body["error"]
        assert (body["finished"], body["failed"], body["workers"]) == (2, 0, 2)
        assert [case["params"] for case in body["cases"]] == [{"tc_noise": 0.5}, {"tc_noise": 1.0}]
        assert body["study"]["grid"] == {"tc_noise": [0.5, 1.0]}
        best = {b["metric"]: b for b in body["best"]}
        assert best["inhomogeneity_steady"]["value"] == min(
            case["metrics"]["inhomogeneity_steady"] for case in body["cases"])
        assert body["figures"] and all(u.endswith(".png") for u in body["figures"])
        fig = c.get(body["figures"][0])
        assert fig.status_code == 200 and fig.headers["content-type"] == "image/png"
        assert set(body["downloads"]) == {"results.parquet", "results.csv", "study.md", "summary.json"}
        table = pq.read_table(io.BytesIO(c.get(body["downloads"]["results.parquet"]).content))
        assert table.num_rows == 2 and table.column("status").to_pylist() == ["done", "done"]
        csv = c.get(body["downloads"]["results.csv"])
        assert csv.headers["content-type"].startswith("text/csv") and len(csv.text.strip().splitlines()) == 3
        assert c.get(body["downloads"]["study.md"]).text.startswith("# Study: api")


@pytest.mark.parametrize(
    ("study", "needle"),
    [
        ({"grid": {"oscillation.perod": [6.0]}}, "oscillation.perod"),
        ({"grid": {"oscillation.amplitude": [0.2]}, "base": {"oscillation": {"enabled": True}}}, "amplitude"),
        ({"furnace": "/etc/passwd", "grid": {"tc_noise": [1.0]}}, "not a shipped furnace"),
        ({"grid": {"tc_noise": [0.1 * i for i in range(1, 12)]}}, "at most 10 per study"),
        ({"base": {"duration": 600.0}, "grid": {"tc_noise": [1.0]}}, "server's limit"),
        ({"base": {}}, "needs a [grid]"),
        ({"monte_carlo": {"n": 3, "mismatch.alpha": {"dist": "uniform", "low": 0.3, "high": -0.3}}}, "high > low"),
        ([1, 2], "object"),
    ],
)
def test_bad_studies_are_422_with_the_reason(tmp_path, small_cfg, study, needle) -> None:
    runner = FakeStudyRunner()
    with make_client(tmp_path, small_cfg, runner, max_study_cases=10, max_duration_s=300.0) as c:
        r = c.post("/api/studies", json=study)
        assert r.status_code == 422, r.text
        assert needle in r.text
        assert c.get("/api/studies").json() == [] and runner.calls == []


def test_unknown_studies_and_files_are_404_and_changes_need_the_token(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg, FakeStudyRunner(), api_token=TOKEN) as c:
        assert c.get("/api/studies/nope").status_code == 404
        assert c.post("/api/studies", json={"grid": {"tc_noise": [1.0]}}).status_code == 401
        # planning is read-only but runs the study's validation: a POST like any other, it needs the token too
        assert c.post("/api/studies/plan", json={"grid": {"tc_noise": [1.0]}}).status_code == 401
        assert c.post("/api/studies/plan", json={"grid": {"tc_noise": [1.0]}},
                      headers={"X-API-Token": TOKEN}).status_code == 200
        r = c.post("/api/studies", json={"grid": {"tc_noise": [1.0]}}, headers={"X-API-Token": TOKEN})
        assert r.status_code == 201
        study_id = r.json()["id"]
        wait_study(c, study_id, {"finished"})
        for name in ("request.json", "../request.json", "figures/../status.json", "cases", "figures/.x.png"):
            assert c.get(f"/api/studies/{study_id}/files/{name}").status_code == 404, name
        assert c.get(f"/api/studies/{study_id}/files/summary.json").status_code == 200
        assert c.post(f"/api/studies/{study_id}/stop", headers={"X-API-Token": TOKEN}).status_code == 409
        assert c.post(f"/api/studies/{study_id}/resume", headers={"X-API-Token": TOKEN}).status_code == 409


def test_stop_then_resume(tmp_path, small_cfg) -> None:
    runner = FakeStudyRunner(block_s=30.0)
    with make_client(tmp_path, small_cfg, runner) as c:
        study_id = c.post("/api/studies", json={"grid": {"tc_noise": [0.5, 1.0]}}).json()["id"]
        wait_study(c, study_id, {"running"})
        assert c.post(f"/api/studies/{study_id}/stop").status_code == 202
        body = wait_study(c, study_id, {"stopped"}, timeout=10)
        assert [case["status"] for case in body["cases"]] == ["pending", "pending"]
        runner.block_s = 0.0
        assert c.post(f"/api/studies/{study_id}/resume").status_code == 202
        body = wait_study(c, study_id, {"finished"}, timeout=10)
        assert body["finished"] == 2 and len(runner.calls) == 2


def test_a_study_going_at_shutdown_is_interrupted_and_resumes_after_restart(tmp_path, small_cfg) -> None:
    with make_client(tmp_path, small_cfg, FakeStudyRunner(block_s=30.0)) as c:
        study_id = c.post("/api/studies", json={"grid": {"tc_noise": [0.5, 1.0]}}).json()["id"]
        wait_study(c, study_id, {"running"})
    with make_client(tmp_path, small_cfg, FakeStudyRunner()) as c:
        body = c.get(f"/api/studies/{study_id}").json()
        assert body["status"] == "interrupted"
        assert c.post(f"/api/studies/{study_id}/resume").status_code == 202
        assert wait_study(c, study_id, {"finished"}, timeout=10)["finished"] == 2


class TimedRunner(FakeStudyRunner):
    """The fake engine, with the timing figures a real study writes: 3 s per case (median), 5 s first load."""

    def __call__(self, spec, cfg, out, **kw):
        import json

        summary = super().__call__(spec, cfg, out, **kw)
        summary["timing"] = {"case_s": 3.0, "load_s": 5.0}
        (out / "summary.json").write_text(json.dumps(summary))
        return summary


def test_plan_says_the_cases_and_an_estimate_from_the_finished_studies(tmp_path, small_cfg) -> None:
    """Issue 27 item 8: before Start, the cases (design points x seeds) and an estimated wall time."""
    plan_doc = {"base": {**BASE, "duration": 24.0}, "grid": {"tc_noise": [0.5, 1.0], "seed": [1, 2, 3]}}
    with make_client(tmp_path, small_cfg, TimedRunner(), study_workers=2) as c:
        first = c.post("/api/studies/plan", json=plan_doc)
        assert first.status_code == 200, first.text
        assert first.json()["estimate_s"] is None and "no study has finished" in first.json()["basis"]
        assert c.post("/api/studies/plan", json={"grid": {"oscillation.perod": [6.0]}}).status_code == 422
        done = c.post("/api/studies", json={"name": "timed", "base": BASE, "grid": {"tc_noise": [0.5, 1.0]}})
        wait_study(c, done.json()["id"], {"finished"})
        plan = c.post("/api/studies/plan", json=plan_doc).json()
    # 6 cases on 2 workers: 3 waves of a 24 s case at 3 s per 12 s case (0.25 s/s), plus the 5 s first load
    assert (plan["cases"], plan["points"], plan["per_point"], plan["workers"]) == (6, 2, 3, 2)
    assert plan["estimate_s"] == pytest.approx(5.0 + 3 * 24.0 * 0.25)
    assert "timed" in plan["basis"]
