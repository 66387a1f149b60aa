"""Stream benchmark (``furnace-twin bench`` calls :func:`stream_bench`).

A real server (uvicorn on 127.0.0.1, a free port, a temporary data directory) runs real
closed loops; websocket clients measure what a browser would see:

- ``stream_fps_min``: 5 clients on one run at real-time speed; frames per second of the
  slowest client: frames received whose samples lie in a whole number of simulated seconds
  ``[t_0, t_0 + T)``, divided by ``T`` (= wall seconds at speed 1).  With t_s = 0.1 s the loop
  makes 10 samples/s, so 10.0 means no frame was lost; ``stream_fps_min_wall`` is the same from
  receive times, ``(n - 1) / (last - first)``, which jitters by a few ms around 10;
- ``stream_latency_p95_ms``: 95th percentile over all clients of receive time minus the
  frame's ``wall_time`` (when the worker computed the sample), same run;
- ``max_speed_rtf_with_clients``: a run at speed ``max`` with 2 clients attached; simulated
  seconds per wall second from the frames' ``t`` and ``wall_time``;
- ``closed_loop_rtf_bare`` and ``max_speed_rtf_ratio``: the same scenario stepped directly in
  this process without the server, and the ratio of the two.
"""

from __future__ import annotations

import asyncio
import json
import logging
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from backend.app import create_app
from backend.loop_factory import DefaultLoopFactory
from backend.settings import Settings
from backend.threaded_server import ThreadedServer
from twin.config import FurnaceConfig
from twin.control.budget import PlanBudget
from twin.scenario import Scenario

log = logging.getLogger(__name__)


def _post(port: int, path: str, body: dict[str, Any] | None = None) -> dict[str, Any]:
    import urllib.request

    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=json.dumps(body or {}).encode(),
                                 headers={"Content-Type": "application/json"}, method="POST")
    with urllib.request.urlopen(req, timeout=60) as r:  # raises on 4xx / 5xx
        result: dict[str, Any] = json.loads(r.read())
    return result


async def _client(port: int, run_id: str, rows: list[tuple[float, float, float, str]], stop_after_s: float) -> None:
    """Receive frames until the stream closes or ``stop_after_s`` of running frames passed."""
    from websockets.asyncio.client import connect

    first_running: float | None = None
    async with connect(f"ws://127.0.0.1:{port}/api/runs/{run_id}/stream", max_size=2**24) as ws:
        async for msg in ws:
            now = time.time()
            f = json.loads(msg)
            rows.append((now, float(f["wall_time"]), float(f["t"]), str(f["status"])))
            if f["status"] == "running":
                first_running = first_running or now
                if now - first_running >= stop_after_s:
                    return


def _attach(port: int, run_id: str, n_clients: int, seconds: float) -> list[list[tuple[float, float, float, str]]]:
    rows: list[list[tuple[float, float, float, str]]] = [[] for _ in range(n_clients)]

    async def main() -> None:
        await asyncio.gather(*(_client(port, run_id, rows[k], seconds) for k in range(n_clients)))

    asyncio.run(main())
    return rows


def _bare_rtf(cfg: FurnaceConfig, scenario: Scenario, factory: DefaultLoopFactory, sim_s: float) -> float:
    loop: Any = factory(cfg, scenario, budget=PlanBudget())
    try:
        t0 = time.perf_counter()
        first = loop.step()
        last = first
        while not loop.done and last.t - first.t < sim_s:
            last = loop.step()
        return float((last.t - first.t) / (time.perf_counter() - t0))
    finally:
        close = getattr(loop, "close", None)
        if callable(close):
            close()


def stream_bench(cfg: FurnaceConfig, *, realtime_s: float = 10.0, max_speed_sim_s: float = 30.0,
                 n_clients: int = 5) -> dict[str, float]:
    """Measure the live stream of a real server; see the module docstring for the keys."""
    factory = DefaultLoopFactory()
    factory.radiation(cfg)  # load the cached exchange factors before timing anything
    factory.truth_radiation(cfg)
    with tempfile.TemporaryDirectory(prefix="furnace-bench-") as tmp:
        settings = Settings(data_dir=Path(tmp), max_concurrent_runs=2, viser_port=0)  # type: ignore[call-arg]
        with ThreadedServer(create_app(settings, cfg, loop_factory=factory)) as srv:
            # 1) real time, five clients
            rt = Scenario.model_validate({"duration": realtime_s + 30.0, "speed": 1.0})
            run_id = _post(srv.port, "/api/runs", rt.model_dump(mode="json"))["id"]
            rows = _attach(srv.port, run_id, n_clients, realtime_s)
            _post(srv.port, f"/api/runs/{run_id}/stop")
            fps, fps_wall, lat = [], [], []
            for client in rows:
                run = [r for r in client if r[3] == "running"]
                if len(run) < 2:
                    fps.append(0.0)
                    fps_wall.append(0.0)
                    continue
                # frames whose sample lies in the half-open window [t_first, t_first + T) of
                # simulated time, per second of (real-time paced) window: exactly 10 at t_s = 0.1 s
                # when no frame is lost, without the few-ms jitter of two receive times
                t_first = run[0][2]
                span = (run[-1][2] - t_first) // 1.0 or run[-1][2] - t_first
                fps.append(sum(1 for r in run if t_first <= r[2] < t_first + span - 1e-9) / span)
                fps_wall.append((len(run) - 1) / (run[-1][0] - run[0][0]))
                lat += [1000.0 * (r[0] - r[1]) for r in run[1:]]  # the first may be a catch-up frame
            # 2) speed max, two clients
            mx = Scenario.model_validate({"duration": max_speed_sim_s, "speed": "max"})
            time.sleep(0.5)  # let the stopped run finalise
            run_id = _post(srv.port, "/api/runs", mx.model_dump(mode="json"))["id"]
            rows = _attach(srv.port, run_id, 2, 1e9)
            run = [r for r in rows[0] if r[3] in ("running", "finished")]
            rtf = (run[-1][2] - run[0][2]) / max(run[-1][1] - run[0][1], 1e-9) if len(run) >= 2 else 0.0
    bare = _bare_rtf(cfg, mx, factory, max_speed_sim_s)
    result = {
        "stream_fps_min": float(min(fps)),
        "stream_fps_min_wall": float(min(fps_wall)),
        "stream_latency_p95_ms": float(np.percentile(lat, 95)) if lat else float("nan"),
        "max_speed_rtf_with_clients": float(rtf),
        "closed_loop_rtf_bare": bare,
        "max_speed_rtf_ratio": float(rtf / bare) if bare > 0 else float("nan"),
    }
    log.info("stream bench: %s", result)
    return result
