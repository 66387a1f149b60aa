"""Findings 1 and 13: Stop while a run is starting, and SIGTERM during a run's set-up (real server, small furnace)."""
import os, signal, subprocess, sys, tempfile, time
import httpx
sys.path.insert(0, "backend")
from backend.core.threaded_server import free_port
tree = os.getcwd()
SERVE = ("import logging, sys\nfrom backend.server import serve\nfrom twin.config import small_config\n"
         "sys.exit(serve(small_config(), host='127.0.0.1', port={port}, viser_port=0, data_dir={data!r}))\n")
LONG = {"reference": {"setpoint": 1100.0, "t_E": 600.0}, "duration": 600.0}
def start():
    port = free_port()
    env = {**os.environ, "PYTHONPATH": tree, "FURNACE_TWIN_PLAN_MAX_S": "3600"}
    p = subprocess.Popen([sys.executable, "-c", SERVE.format(port=port, data=tempfile.mkdtemp())], cwd=tree, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    for _ in range(600):
        try:
            if httpx.get(url + "/api/health", timeout=2).status_code == 200: break
        except httpx.HTTPError: time.sleep(0.2)
    return p, url
def starting(url):
    rid = httpx.post(url + "/api/runs", json=LONG, timeout=300).json()["id"]
    while httpx.get(f"{url}/api/runs/{rid}", timeout=10).json()["status"] != "starting": time.sleep(0.1)
    time.sleep(2.0)
    return rid
p, url = start()
try:
    rid = starting(url)
    t0 = time.monotonic(); httpx.post(f"{url}/api/runs/{rid}/stop", timeout=10)
    while time.monotonic() - t0 < 30:
        st = httpx.get(f"{url}/api/runs/{rid}", timeout=10).json()["status"]
        if st != "starting": break
        time.sleep(0.1)
    print(f"stop while starting: status {st!r} after {time.monotonic() - t0:.1f} s")
    rid = starting(url) if st != "starting" else rid
    t0 = time.monotonic(); p.send_signal(signal.SIGTERM); p.wait(timeout=120)
    print(f"SIGTERM during set-up: exited after {time.monotonic() - t0:.1f} s")
finally:
    if p.poll() is None: p.kill()
