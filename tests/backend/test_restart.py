"""Kill the server (a real process, SIGKILL) in the middle of a run, restart it on the same data
directory: the run is listed as interrupted and its data up to the crash is readable."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np

from backend.core.threaded_server import free_port

SERVE = (
    "import sys, logging; logging.basicConfig(level=logging.INFO);"
    "from backend.server import serve; from twin.config import small_config;"
    "sys.exit(serve(small_config(), host='127.0.0.1', port=int(sys.argv[1]), viser_port=int(sys.argv[2]),"
    " data_dir=sys.argv[3], rerun_web_port=0))"  # no rerun web viewer (its default port may be taken)
)


def start_server(data: Path, log: Path) -> tuple[subprocess.Popen, str]:
    port = free_port()
    fh = open(log, "ab")
    proc = subprocess.Popen([sys.executable, "-c", SERVE, str(port), str(free_port()), str(data)],
                            stdout=fh, stderr=subprocess.STDOUT, env=dict(os.environ))
    url = f"http://127.0.0.1:{port}"
    end = time.monotonic() + 60
    while True:
        try:
            if httpx.get(f"{url}/api/health", timeout=2).status_code == 200:
                return proc, url
        except httpx.TransportError:
            pass
        if time.monotonic() > end or proc.poll() is not None:
            proc.kill()
            raise AssertionError(f"server did not start:\n{log.read_text()[-3000:]}")
        time.sleep(0.2)


def test_killed_server_leaves_an_interrupted_readable_run(tmp_path, isolated_home) -> None:
    data, log = tmp_path / "data", tmp_path / "server.log"
    proc, url = start_server(data, log)
    try:
        run_id = httpx.post(f"{url}/api/runs", json={"duration": 300.0, "speed": 2.0}, timeout=30).json()["id"]
        end = time.monotonic() + 180
        while True:  # the database holds the latest values of the last flush (every 2 s wall)
            run = httpx.get(f"{url}/api/runs/{run_id}", timeout=10).json()
            if (run.get("latest") or {}).get("t", 0.0) >= 6.0:
                break
            assert run["status"] in ("queued", "starting", "running"), run
            assert time.monotonic() < end, f"no progress:\n{log.read_text()[-3000:]}"
            time.sleep(0.2)
        t_seen = run["latest"]["t"]
    finally:
        proc.kill()  # SIGKILL: no shutdown handler runs
        proc.wait(timeout=30)

    proc, url = start_server(data, log)
    try:
        run = httpx.get(f"{url}/api/runs/{run_id}", timeout=10).json()
        assert run["status"] == "interrupted"
        assert run["latest"]["t"] >= t_seen
        assert run["metrics"] is not None and run["metrics"]["mean_error_transient_max"] is not None
        z = np.load(io.BytesIO(httpx.get(f"{url}/api/runs/{run_id}/timeseries", timeout=30).content))
        # flushed at least once with t >= 6 s: at 10 samples per second that is > 50 samples
        assert len(z["t"]) > 50 and z["field_hat"].shape[0] == len(z["t_field"])
        rrd = httpx.get(f"{url}/api/runs/{run_id}/recording", timeout=30)
        assert rrd.status_code == 200
        path = tmp_path / "crashed.rrd"
        path.write_bytes(rrd.content)
        rerun = Path(sys.executable).with_name("rerun")
        out = subprocess.run([str(rerun), "rrd", "stats", str(path)], capture_output=True, text=True,
                             timeout=120, env={**os.environ, "HOME": str(isolated_home)})
        assert out.returncode == 0, out.stderr[-2000:]
        assert "/temperature/T_mean_hat" in out.stdout and "/field/estimated" in out.stdout
        # the server works on: a run can be stopped-state queried and new runs are accepted
        assert httpx.post(f"{url}/api/runs/{run_id}/stop", timeout=10).status_code == 409
    finally:
        proc.terminate()
        proc.wait(timeout=60)
