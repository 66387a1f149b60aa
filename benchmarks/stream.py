"""Stream and memory benchmark of the server (``furnace-twin bench`` calls :func:`stream_bench`).

A real server (``python -m benchmarks.stream_server``: the real app and loops, 127.0.0.1, a temporary data
directory) runs in its own process, so its memory is its own and its clients (here, asyncio websockets in
this process) do not share its interpreter, as browsers would not.  Figures:

Load (``load_s`` wall seconds): ``background_runs`` runs at speed ``max`` with no client, and one live run
whose speed makes ``client_fps`` samples per second (t_s = 0.1 s: speed 2 for 20 frames/s) watched by
``stream_clients`` websocket clients:

- ``stream_fps_min``: frames per second of the slowest client: frames whose samples lie in a whole number
  of simulated seconds [t_0, t_0 + T), divided by the wall time T / speed (``client_fps`` = no frame lost);
  ``stream_fps_min_wall`` the same from receive times, (n - 1) / (last - first);
- ``stream_latency_p95_ms``, ``stream_latency_max_ms``: receive time minus the frame's ``wall_time`` (when
  the worker computed the sample), over all clients;
- ``background_rtf_min``: simulated s per wall s of the slowest background run meanwhile.

Long run (``long_sim_s`` simulated seconds at speed ``max``, 2 clients attached):

- ``rss_growth_mb``: the server's peak memory during the run minus its value once the run had gone
  ``baseline_sim_s`` (its first flushes, files and plans done), sampled every 0.5 s; the memory of the
  server's process tree (the server, its fork server and the run's own process) as proportional set
  size, so pages they share count once;
  ``rss_baseline_mb``, ``rss_peak_mb``, ``rss_after_mb`` (after the run ended), ``long_run_sim_s``,
  ``long_run_rtf`` (its speed: simulated s per wall s);
- ``closed_loop_rtf_bare``: the same scenario stepped in this process without a server, over its first
  ``bare_sim_s`` simulated seconds (240 s: the paper's heat-up and hold, with the re-plan in the hold), waiting
  for a re-plan as the server's run at speed max does (its simulated time stands still until the plan is in);
  ``max_speed_rtf_with_clients``: the long run's own speed over the same simulated span (from the first frame
  its clients received), from its frames' ``t`` and ``wall_time`` (when the run's process computed the sample);
  their ratio ``max_speed_rtf_ratio``.  Like for like, the same span and the same run: until stop 34 the ratio
  set the whole hour's speed against the bare loop's first minute, where a sample is cheaper (bare loop, default
  furnace: rtf 29 over 0-60 s, 21 over 60-240 s, 19-22 later) and which stepped on while its re-plan was being
  solved (the server's run waits for it, as the CLI's inline re-plan does).  Measured on a machine loaded by a
  niced mutation run, one bench each: the old way 0.46; the same span 0.48 (server 15.1, bare 31.8); the same span
  and the bare loop waiting for its re-plan 1.07 (server 17.4, bare 16.3), and 0.73 in a second run (13.6, 18.7).
  Most of the gap was the re-plan's wait and the phases, not the server.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

from backend.core.threaded_server import free_port
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget
from twin.scenario import Scenario

log = logging.getLogger(__name__)

Row = tuple[float, float, float, str]  # receive time, frame wall_time, frame t, status


def _call(port: int, method: str, path: str, body: Any = None, timeout: float = 60.0) -> Any:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=data, method=method,
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=timeout) as r:  # raises on 4xx / 5xx
        return json.loads(r.read())


def _tree(pid: int) -> list[int]:
    """``pid`` and its descendants (the server, its fork server and the runs' processes)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        children.setdefault(ppid, []).append(int(entry))
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(children.get(p, []))
    return out


def _memory_mb(pid: int) -> float:
    """Proportional set size (PSS) of the server's process tree in MB: the pages a process shares with
    another (the fork server's imported modules in each run's process) count once in total."""
    total = 0
    for p in _tree(pid):
        try:
            with open(f"/proc/{p}/smaps_rollup") as f:
                total += next(int(line.split()[1]) for line in f if line.startswith("Pss:"))
        except (OSError, StopIteration):
            continue  # ended meanwhile
    return total / 1024.0


class _Server:
    """``python -m benchmarks.stream_server`` as a child process (module docstring)."""

    def __init__(self, cfg: FurnaceConfig, folder: Path, max_runs: int, extra: tuple[str, ...] = ()) -> None:
        self.port = free_port()
        cfg_file = folder / "furnace.json"
        cfg_file.write_text(cfg.model_dump_json())
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.stream_server", "--config-json", str(cfg_file), "--data-dir",
             str(folder / "data"), "--port", str(self.port), "--max-runs", str(max_runs), *extra],
            stdin=subprocess.DEVNULL, env={**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})

    def wait_ready(self, timeout: float = 600.0) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                raise RuntimeError(f"the bench server exited with status {self.proc.returncode}")
            try:
                if _call(self.port, "GET", "/api/health", timeout=5)["radiation"] == "ready":
                    return
            except OSError:
                pass
            time.sleep(0.2)
        raise RuntimeError("the bench server's radiation model was not ready in time")

    def start_run(self, scenario: dict[str, Any]) -> str:
        body = Scenario.model_validate(scenario).model_dump(mode="json")
        run_id: str = _call(self.port, "POST", "/api/runs", body)["id"]
        return run_id

    def run(self, run_id: str) -> dict[str, Any]:
        got: dict[str, Any] = _call(self.port, "GET", f"/api/runs/{run_id}")
        return got

    def wait_status(self, run_id: str, statuses: set[str], timeout: float = 600.0) -> dict[str, Any]:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            body = self.run(run_id)
            if body["status"] in statuses:
                return body
            time.sleep(0.1)
        raise RuntimeError(f"run {run_id} never reached {statuses}")

    def stop(self, run_id: str) -> None:
        try:
            _call(self.port, "POST", f"/api/runs/{run_id}/stop")
        except OSError:
            pass  # already ended

    def close(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=10)


async def _client(port: int, run_id: str, rows: list[Row], stop_after_s: float) -> None:
    """Receive frames until the stream closes or ``stop_after_s`` wall seconds of running frames passed."""
    from websockets.asyncio.client import connect

    first: float | None = None
    async with connect(f"ws://127.0.0.1:{port}/api/runs/{run_id}/stream", max_size=2**24) as ws:
        async for msg in ws:
            now = time.time()
            f = json.loads(msg)
            rows.append((now, float(f["wall_time"]), float(f["t"]), str(f["status"])))
            if f["status"] == "running":
                first = first or now
                if now - first >= stop_after_s:
                    return


def _attach(port: int, run_id: str, n_clients: int, seconds: float) -> list[list[Row]]:
    rows: list[list[Row]] = [[] for _ in range(n_clients)]

    async def main() -> None:
        await asyncio.gather(*(_client(port, run_id, rows[k], seconds) for k in range(n_clients)))

    asyncio.run(main())
    return rows


def _client_figures(rows: list[list[Row]], speed: float) -> dict[str, float]:
    fps, fps_wall, lat = [], [], []
    for client in rows:
        run = [r for r in client if r[3] == "running"]
        if len(run) < 2:
            fps.append(0.0)
            fps_wall.append(0.0)
            continue
        t_first = run[0][2]
        span = (run[-1][2] - t_first) // 1.0 or run[-1][2] - t_first  # whole simulated seconds
        fps.append(sum(1 for r in run if t_first <= r[2] < t_first + span - 1e-9) / (span / speed))
        fps_wall.append((len(run) - 1) / (run[-1][0] - run[0][0]))
        lat += [1000.0 * (r[0] - r[1]) for r in run[1:]]  # the first may be a catch-up frame
    return {"stream_fps_min": float(min(fps)), "stream_fps_min_wall": float(min(fps_wall)),
            "stream_latency_p95_ms": float(np.percentile(lat, 95)) if lat else float("nan"),
            "stream_latency_max_ms": float(np.max(lat)) if lat else float("nan")}


def _load_phase(srv: _Server, *, n_clients: int, client_fps: float, t_s: float, load_s: float,
                background_runs: int) -> dict[str, float]:
    background = [srv.start_run({"duration": 3600.0, "speed": "max", "seed": k}) for k in range(background_runs)]
    for run_id in background:
        srv.wait_status(run_id, {"running"})
    speed = client_fps * t_s  # samples per wall second = speed / t_s
    live = srv.start_run({"duration": 3600.0, "speed": speed})
    srv.wait_status(live, {"running"})
    before = {r: (time.monotonic(), (srv.run(r)["latest"] or {}).get("t", 0.0)) for r in background}
    rows = _attach(srv.port, live, n_clients, load_s)
    rtf = []
    for r, (w0, t0) in before.items():
        t1 = (srv.run(r)["latest"] or {}).get("t", 0.0)
        rtf.append((t1 - t0) / (time.monotonic() - w0))
    for r in [live, *background]:
        srv.stop(r)
    for r in [live, *background]:
        srv.wait_status(r, {"stopped", "finished", "error", "interrupted"})
    out = _client_figures(rows, speed)
    out.update(stream_clients=float(n_clients), stream_fps_target=float(client_fps),
               stream_background_runs=float(background_runs),
               background_rtf_min=float(min(rtf)) if rtf else float("nan"))
    return out


def _long_phase(srv: _Server, *, long_sim_s: float, baseline_sim_s: float, window_sim_s: float) -> dict[str, float]:
    run_id = srv.start_run({"duration": long_sim_s, "speed": "max"})
    rows: list[list[Row]] = []
    samples: list[tuple[float, float]] = []  # (simulated t, RSS MB)

    async def watch() -> None:
        rows.extend([[], []])
        clients = [asyncio.create_task(_client(srv.port, run_id, rows[k], 1e9)) for k in range(2)]
        while not all(c.done() for c in clients):
            t = rows[0][-1][2] if rows[0] else 0.0
            samples.append((t, _memory_mb(srv.proc.pid)))
            await asyncio.sleep(0.5)
        # and at the end (a short run on a quiet machine can end between two samples of the loop above)
        samples.append((rows[0][-1][2] if rows[0] else long_sim_s, _memory_mb(srv.proc.pid)))

    asyncio.run(watch())
    body = srv.wait_status(run_id, {"finished", "stopped", "error", "interrupted"})
    if body["status"] != "finished":
        raise RuntimeError(f"the long run ended {body['status']}: {body['error']}")
    after = _memory_mb(srv.proc.pid)
    base = [m for t, m in samples if t >= baseline_sim_s]
    run = [r for r in rows[0] if r[3] in ("running", "finished")]
    return {"rss_baseline_mb": base[0], "rss_peak_mb": max(base), "rss_growth_mb": max(base) - base[0],
            "rss_after_mb": after, "long_run_sim_s": long_sim_s, "long_run_rtf": _frames_rtf(run),
            "max_speed_rtf_with_clients": _frames_rtf([r for r in run if r[2] <= window_sim_s + 1e-9])}


def _frames_rtf(frames: list[Row]) -> float:
    """Simulated s per wall s between the first and the last of ``frames`` (their ``t`` and ``wall_time``).

    >>> _frames_rtf([(0.0, 100.0, 0.0, "running"), (0.0, 101.0, 20.0, "running"), (0.0, 102.0, 30.0, "running")])
    15.0
    """
    if len(frames) < 2:
        return float("nan")
    return float((frames[-1][2] - frames[0][2]) / max(frames[-1][1] - frames[0][1], 1e-9))


def _bare_rtf(cfg: FurnaceConfig, sim_s: float) -> float:
    from backend.runs.loop_factory import DefaultLoopFactory

    factory = DefaultLoopFactory(processes=False)  # this process, to compare with the server's rate
    loop: Any = factory(cfg, Scenario.model_validate({"duration": 3600.0, "speed": "max"}), budget=PlanBudget())
    try:
        t0 = time.perf_counter()
        first = last = loop.step()
        while not loop.done and last.t - first.t < sim_s:
            while loop.replanning:  # as the server's run does at speed max (backend.runs.worker.RunWorker.advance)
                time.sleep(0.02)
            last = loop.step()
        return float((last.t - first.t) / (time.perf_counter() - t0))
    finally:
        loop.close()


def stream_bench(cfg: FurnaceConfig, *, n_clients: int = 20, client_fps: float = 20.0, load_s: float = 20.0,
                 background_runs: int = 2, long_sim_s: float = 3600.0, baseline_sim_s: float = 120.0,
                 bare_sim_s: float = 240.0, server_args: tuple[str, ...] = ()) -> dict[str, float]:
    """Measure the stream under load and the memory over a long run; see the module docstring."""
    result: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="furnace-bench-") as tmp:
        srv = _Server(cfg, Path(tmp), max_runs=background_runs + 1, extra=server_args)
        try:
            srv.wait_ready()
            log.info("bench: %d clients at %g frames/s with %d runs at speed max", n_clients, client_fps,
                     background_runs)
            result.update(_load_phase(srv, n_clients=n_clients, client_fps=client_fps, t_s=cfg.sampling.t_s,
                                      load_s=load_s, background_runs=background_runs))
            if long_sim_s > 0:
                log.info("bench: a %g s run at speed max (memory)", long_sim_s)
                result.update(_long_phase(srv, long_sim_s=long_sim_s, baseline_sim_s=min(baseline_sim_s,
                                                                                          long_sim_s / 2),
                                          window_sim_s=min(bare_sim_s, long_sim_s)))
        finally:
            srv.close()
    if long_sim_s > 0:
        bare = _bare_rtf(cfg, bare_sim_s)
        result.update(closed_loop_rtf_bare=bare, max_speed_rtf_ratio=result["max_speed_rtf_with_clients"] / bare)
    log.info("stream bench: %s", result)
    return result
