"""Issue 15, findings 8 and 13 (disk and interrupted runs).

Finding 8: a 3600 s run at speed max left 175 MB and wrote 1.1 GB (the npz rewritten whole at every
flush); no quota or retention.  Finding 13: interrupted runs had ``ended_at: null`` and a recording
that fails ``rerun rrd verify`` (no footer).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from backend.storage.repository import RunRepository
from conftest import fake_factory, wait_status
from twin.runs import record as record_module
from twin.runs.record import load_arrays


def client(tmp_path, cfg, factory=None, **settings) -> TestClient:
    s = Settings(data_dir=tmp_path / "data", viser_port=0, **settings)
    return TestClient(create_app(s, cfg, loop_factory=factory or fake_factory()), base_url="http://127.0.0.1")


def test_finding_08_series_appended_not_rewritten(tmp_path, small_cfg, monkeypatch) -> None:
    """Bytes of time series written over a run with many flushes: about the final file's size, not
    flushes x half of it."""
    written: list[int] = []
    save = record_module.save_arrays

    def counting(path, arrays, *, compress=True):
        save(path, arrays, compress=compress)
        written.append(Path(path).stat().st_size)

    monkeypatch.setattr(record_module, "save_arrays", counting)
    monkeypatch.setattr("twin.runs.series_store.save_arrays", counting)
    monkeypatch.setattr("twin.runs.folder.save_arrays", counting)
    with client(tmp_path, small_cfg, fake_factory(step_cost_s=0.002), flush_interval_s=0.05) as c:
        run_id = c.post("/api/runs", json={"duration": 60.0}).json()["id"]  # 600 samples at speed max
        wait_status(c, run_id, {"finished"})
        path = tmp_path / "data" / "runs" / run_id / "timeseries.npz"
        final = path.stat().st_size
        assert len(written) > 10  # many flushes happened
        # header + parts + the consolidated file: ~2x the final size (a rewrite at every flush was ~flushes/2 x)
        assert sum(written) < 2.5 * final, (sum(written), final, len(written))
        a = load_arrays(path)
        assert len(a["t"]) == 600 and a["field_hat"].shape[0] == 600
        np.testing.assert_allclose(np.diff(a["t"]), 0.1, atol=1e-9)  # every sample once, in order
        assert not (path.parent / "timeseries.parts").exists()


def test_finding_08_parts_equal_the_record(tmp_path, small_cfg) -> None:
    """The consolidated parts are exactly RunRecord.arrays() (the layout of product.md), events included."""
    from conftest import FakeLoop
    from twin.runs.series_store import SeriesStore, consolidate, load_parts, write_parts
    from twin.scenario import Scenario

    loop = FakeLoop(small_cfg, Scenario(duration=5.0))
    store = SeriesStore(tmp_path)
    for k in range(50):
        loop.step()
        if k == 20:
            loop.events.append("something happened")
        if k % 7 == 0:
            store.append(loop.record)
    store.append(loop.record)
    expected = loop.record.arrays()
    got = load_parts(tmp_path)
    assert set(got) == set(expected)
    for key, value in expected.items():
        np.testing.assert_array_equal(got[key], value, err_msg=key)
    # written part by part through raw files (the server's way): the same arrays, dtypes and shapes
    write_parts(tmp_path, tmp_path / "streamed.npz")
    streamed = load_arrays(tmp_path / "streamed.npz")
    assert set(streamed) == set(expected)
    for key, value in expected.items():
        np.testing.assert_array_equal(streamed[key], value, err_msg=key)
        assert streamed[key].dtype == np.asarray(value).dtype, key
    assert not list(tmp_path.glob("streamed.npz.*"))  # its raw files and temporary are gone
    # a part cut short by a crash: the series ends before it and stays readable
    last = sorted((tmp_path / "timeseries.parts").glob("part-*.npz"))[-1]
    last.write_bytes(last.read_bytes()[:100])
    cut = load_parts(tmp_path)
    assert len(cut["t"]) < 50
    arrays = consolidate(tmp_path, tmp_path / "timeseries.npz")
    assert len(load_arrays(tmp_path / "timeseries.npz")["t"]) == len(arrays["t"]) > 40
    for key, value in cut.items():
        np.testing.assert_array_equal(arrays[key], value, err_msg=key)


def test_finding_08_written_parts_equal_their_concatenation(tmp_path) -> None:
    """Oracle: write_parts gives what np.concatenate of each series over the parts gives (load_parts): a series
    that first appears in a later part, texts of different lengths, a series whose dtype changes (kept in
    memory then, promoted as np.concatenate promotes), and a cut last part that ends the series."""
    from twin.runs.record import save_arrays
    from twin.runs.series_store import load_parts, parts_dir, write_parts

    d = parts_dir(tmp_path)
    save_arrays(d / "header.npz", {"x": np.arange(3.0), "setpoint": np.array(1000.0)}, compress=False)
    rng = np.random.default_rng(0)
    parts = [
        {"t": np.array([0.0, 0.1, 0.2]), "field": rng.random((3, 2, 2)).astype(np.float32),
         "event_text": np.array(["abc"])},
        {"t": np.array([0.3, 0.4]), "field": rng.random((2, 2, 2)).astype(np.float32),
         "event_text": np.array(["a longer text", "x"]), "tc_status": np.ones((2, 4), np.int8)},
        {"t": np.array([5, 6]), "field": rng.random((2, 2, 2)).astype(np.float32),  # t as integers here
         "event_text": np.array([], dtype="<U1"), "tc_status": np.zeros((2, 4), np.int8)},
    ]
    for i, arrays in enumerate(parts, start=1):
        save_arrays(d / f"part-{i:06d}.npz", arrays, compress=False)
    (d / "part-000004.npz").write_bytes(b"PK\x03\x04 cut short")
    expected = load_parts(tmp_path)
    assert len(expected["t"]) == 7 and expected["event_text"].dtype == np.dtype("<U13")
    write_parts(tmp_path, tmp_path / "timeseries.npz")
    got = load_arrays(tmp_path / "timeseries.npz")
    assert list(got) == list(expected)
    for key, value in expected.items():
        np.testing.assert_array_equal(got[key], value, err_msg=key)
        assert got[key].dtype == value.dtype and got[key].shape == value.shape, key


def test_finding_08_live_download_and_series(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg, flush_interval_s=0.1) as c:
        run_id = c.post("/api/runs", json={"duration": 600.0, "speed": 5.0}).json()["id"]
        wait_status(c, run_id, {"running"})
        time.sleep(1.0)
        r = c.get(f"/api/runs/{run_id}/timeseries")
        assert r.status_code == 200
        import io

        with np.load(io.BytesIO(r.content)) as z:
            assert len(z["t"]) > 5
        assert not list((tmp_path / "data" / "runs" / run_id).glob(".timeseries-*"))  # the temporary is gone
        c.post(f"/api/runs/{run_id}/stop")
        wait_status(c, run_id, {"stopped"})


def test_finding_08_quota_refuses_and_stops(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg, data_quota_mb=1.0) as c:
        r = c.post("/api/runs", json={"duration": 3600.0})
        assert r.status_code == 507 and "quota" in r.json()["detail"], r.text
        health = c.get("/api/health").json()
        assert health["disk"]["quota_mb"] == 1.0 and health["disk"]["free_mb"] > 0
        # a run that fits the estimate but passes the quota while running stops with a reason, data kept
        (tmp_path / "data" / "ballast.bin").write_bytes(b"\0" * 700_000)
        run_id = c.post("/api/runs", json={"duration": 3.0, "speed": 0.2}).json()["id"]  # ~10 KB estimated
        (tmp_path / "data" / "more-ballast.bin").write_bytes(b"\0" * 400_000)
        body = wait_status(c, run_id, {"error", "finished"}, timeout=60)
        assert body["status"] == "error" and "quota" in body["error"], body
        assert (tmp_path / "data" / "runs" / run_id / "timeseries.npz").is_file()


def test_finding_08_retention_deletes_old_ended_runs(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg) as c:
        ids = [c.post("/api/runs", json={"duration": 0.5}).json()["id"] for _ in range(2)]
        for run_id in ids:
            wait_status(c, run_id, {"finished"})
    repo = RunRepository(tmp_path / "data" / "runs.sqlite3")
    repo._exec("UPDATE runs SET created_at = created_at - 10 * 86400 WHERE id = ?", (ids[0],))
    repo.close()
    with client(tmp_path, small_cfg, retention_days=7.0) as c:
        assert [r["id"] for r in c.get("/api/runs").json()] == [ids[1]]
        assert not (tmp_path / "data" / "runs" / ids[0]).exists()
        assert (tmp_path / "data" / "runs" / ids[1]).is_dir()


CRASH = """
import os, sys, time
from pathlib import Path
import rerun as rr
from backend.storage.repository import RunRepository
from twin.runs.folder import RunFolder
from backend.storage.recording import RecordingSink
from twin.config import small_config
from twin.runs.series_store import SeriesStore
sys.path.insert(0, {tests!r})
from conftest import FakeLoop
from twin.scenario import Scenario
data = Path({data!r})
repo = RunRepository(data / "runs.sqlite3")
sc = Scenario(duration=30.0)
repo.create_run("crashed00001", sc.to_json(), status="running")
files = RunFolder(data / "runs" / "crashed00001")
files.folder.mkdir(parents=True)
cfg = small_config()
sink = RecordingSink(cfg, "crashed00001", files.recording, tc_positions=cfg.tc_positions())
loop, store = FakeLoop(cfg, sc), SeriesStore(files.folder)
for k in range(40):
    sink.add(loop.step())
    if k % 10 == 9:
        store.append(loop.record)
        sink.flush()
os._exit(0)  # like kill -9: no close, no footer, no consolidation
"""


def test_finding_13_interrupted_run_gets_end_time_and_readable_recording(tmp_path, small_cfg, isolated_home) -> None:
    data = tmp_path / "data"
    data.mkdir()
    tests = str(Path(__file__).resolve().parent)
    subprocess.run([sys.executable, "-c", CRASH.format(data=str(data), tests=tests)], check=True, cwd=tests,
                   env={**os.environ, "HOME": str(isolated_home)}, timeout=120)
    folder = data / "runs" / "crashed00001"
    rerun = str(Path(sys.executable).parent / "rerun")
    before = subprocess.run([rerun, "rrd", "verify", str(folder / "recording.rrd")], capture_output=True, text=True)
    assert "without error" not in before.stdout + before.stderr  # what a crash leaves
    with client(tmp_path, small_cfg) as c:
        body = c.get("/api/runs/crashed00001").json()
        assert body["status"] == "interrupted" and body["ended_at"] is not None
        assert body["created_at"] <= body["ended_at"] <= time.time()
        assert body["metrics"] is not None  # from the consolidated series
    after = subprocess.run([rerun, "rrd", "verify", str(folder / "recording.rrd")], capture_output=True, text=True)
    assert "without error" in after.stdout + after.stderr, after.stdout + after.stderr
    assert len(load_arrays(folder / "timeseries.npz")["t"]) == 40


@pytest.mark.parametrize("final", ["stopped"])
def test_finding_13_stopped_run_has_end_time(tmp_path, small_cfg, final) -> None:
    with client(tmp_path, small_cfg) as c:
        run_id = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0}).json()["id"]
        wait_status(c, run_id, {"running"})
        c.post(f"/api/runs/{run_id}/stop")
        assert wait_status(c, run_id, {final})["ended_at"] is not None
