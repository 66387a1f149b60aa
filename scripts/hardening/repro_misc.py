"""Before/after evidence for findings 3, 5, 6, 7, 12, 13 (speed, ended_at) and 8 (bytes written).
Run with PYTHONPATH=<tree> from that tree; loopback only (TestClient in process)."""
import json, os, sys, time, tempfile
from pathlib import Path
sys.path.insert(0, "tests/backend")
from conftest import fake_factory, wait_status
from fastapi.testclient import TestClient
from backend.app import create_app
from backend.core.settings import Settings
from twin.config import small_config
cfg = small_config()
tmp = Path(tempfile.mkdtemp())
def show(name, r):
    body = r.content[:120]
    print(f"{name:55s} -> {r.status_code} {len(r.content)} B {body!r}")
kw = {}
try:
    s = Settings(data_dir=tmp / "d", viser_port=0, api_token="s3cret")
    print("finding 12: token 's3cret' (6 chars) accepted by Settings")
except Exception as e:
    print("finding 12: token 's3cret' refused:", str(e).splitlines()[-1][:100])
s = Settings(data_dir=tmp / "d", viser_port=0)
c = TestClient(create_app(s, cfg, loop_factory=fake_factory()), base_url="http://127.0.0.1", raise_server_exceptions=False)
with c:
    for lit in ("NaN", "Infinity", "1e999"):
        show(f"finding 3: POST duration={lit}", c.post("/api/runs", content=f'{{"duration": {lit}}}'.encode(), headers={"Content-Type": "application/json"}))
    r = c.post("/api/runs", json={"speed": True, "duration": 0.5})
    show("finding 13: POST speed=true", r)
    show("finding 5: text/plain POST", c.post("/api/runs", content=b'{"duration": 0.5}', headers={"Content-Type": "text/plain"}))
    show("finding 5: POST Origin evil", c.post("/api/runs", json={"duration": 0.5}, headers={"Origin": "http://evil.example"}))
    show("finding 5: GET Host evil", c.get("/api/health", headers={"Host": "evil.example"}))
    big = b'{"reference": {"setpoint": "' + b"x" * 5_000_000 + b'"}}'
    r = c.post("/api/runs", content=big, headers={"Content-Type": "application/json"})
    show("finding 6: 5 MB body (422 echo size)", r)
    pts = [[0.5 * i, 400.0] for i in range(5000)]
    r = c.post("/api/runs", json={"reference": {"points": pts}, "duration": 0.5})
    show("finding 7: 5000 points", r)
    for run in c.get("/api/runs").json():
        try: wait_status(c, run["id"], {"finished", "error", "stopped"}, timeout=30)
        except AssertionError: pass
    r = c.get("/api/runs")
    print(f"{'finding 7: GET /api/runs size':55s} -> {len(r.content)} B for {len(r.json())} runs")
    rid = c.post("/api/runs", json={"duration": 60.0, "speed": 1.0}).json()["id"]
    wait_status(c, rid, {"running"})
    c.post(f"/api/runs/{rid}/stop"); print("finding 13: stopped run ended_at:", wait_status(c, rid, {"stopped"})["ended_at"] is not None)
# finding 8: bytes written by the time-series flushes of a 60 s run at speed max, flush every 0.05 s
import twin.runs.record as rec
written = []
orig = rec.save_arrays
def counting(path, arrays, *, compress=True):
    orig(path, arrays, compress=compress); written.append(Path(path).stat().st_size)
rec.save_arrays = counting
import twin.runs.folder as rf; rf.save_arrays = counting
try:
    import twin.runs.series_store as ss; ss.save_arrays = counting
except ImportError:
    pass
s = Settings(data_dir=tmp / "e", viser_port=0, flush_interval_s=0.05)
with TestClient(create_app(s, cfg, loop_factory=fake_factory(step_cost_s=0.002)), base_url="http://127.0.0.1") as c:
    rid = c.post("/api/runs", json={"duration": 60.0}).json()["id"]
    wait_status(c, rid, {"finished"})
    final = (tmp / "e" / "runs" / rid / "timeseries.npz").stat().st_size
print(f"finding 8: 600 samples, {len(written)} writes, {sum(written)/1e6:.1f} MB written for a {final/1e6:.2f} MB file ({sum(written)/final:.1f}x)")
