"""``python -m benchmarks.dashboard``: how busy the dashboard keeps the browser while a run streams.

A server on the small furnace (in this process, a temporary data directory), Debian's chromium through
playwright, one run started from the page's form (800 K in 20 s, 600 s at the given speed).  Every
``--window`` seconds of the run it reports, for that window:

* ``busy_pct``: the share of the page's main thread spent in long tasks (over 50 ms, chromium's
  ``longtask`` entries), mostly the charts' redraws;
* ``fill_ms``: the wall time of two ``page.fill`` calls into the live change form (what a user typing a new
  setpoint waits for);
* ``frames``: the samples the page holds.

and at the end their medians as JSON.  Timing figures: compare two versions in one sitting (A B A B), never
across machines.  ``--chromium`` for another browser binary.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run"]
LONG_TASKS = ("window.longTasks = []; new PerformanceObserver((l) => { for (const e of l.getEntries()) "
              "window.longTasks.push([e.startTime, e.duration]); }).observe({ entryTypes: ['longtask'] });")


def measure(speed: str = "2", windows: int = 4, window_s: float = 10.0, chromium: str = CHROMIUM) -> dict[str, Any]:
    """The per-window figures and their medians (module docstring)."""
    import httpx
    from playwright.sync_api import sync_playwright

    from backend.app import create_app
    from backend.core.settings import Settings
    from backend.core.threaded_server import ThreadedServer, free_port
    from twin.config import small_config

    rows: list[dict[str, float]] = []
    with tempfile.TemporaryDirectory() as data:
        settings = Settings(data_dir=Path(data))
        with ThreadedServer(create_app(settings, small_config()), free_port()) as srv, sync_playwright() as p:
            with httpx.Client(base_url=srv.url, timeout=10) as c:
                while c.get("/api/health").json()["radiation"] != "ready":
                    time.sleep(0.1)
                browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS, headless=True)
                page = browser.new_page(viewport={"width": 1500, "height": 950})
                page.goto(srv.url, timeout=120_000)
                page.wait_for_function("document.getElementById('server-state').textContent.startsWith('server ok')",
                                       timeout=120_000)
                page.check("input[name=refmode][value=transition]")
                page.fill("input[name=setpoint]", "800")
                page.fill("input[name=t_E]", "20")
                page.fill("input[name=duration]", "600")
                page.fill("input[name=speed]", speed)
                page.set_checked("input[name=osc]", False)
                page.click("#start-btn")
                page.wait_for_function("state.run && state.run.status === 'running'", timeout=180_000)
                page.evaluate(LONG_TASKS)
                for _ in range(windows):
                    t0 = page.evaluate("performance.now()")
                    time.sleep(window_s)
                    t1 = page.evaluate("performance.now()")
                    tasks = page.evaluate("window.longTasks")
                    page.evaluate("window.longTasks = []")
                    busy = sum(d for start, d in tasks if start >= t0)
                    w0 = time.monotonic()
                    page.fill("#new-setpoint", "750")
                    page.fill("#new-tE", "10")
                    fill = time.monotonic() - w0
                    rows.append({"busy_pct": 100.0 * busy / (t1 - t0), "fill_ms": 1000.0 * fill,
                                 "frames": float(page.evaluate("state.series ? state.series.t.length : 0"))})
                c.post(f"/api/runs/{page.evaluate('state.runId')}/stop")
                browser.close()
    return {"speed": speed, "windows": rows,
            "busy_pct_median": statistics.median(r["busy_pct"] for r in rows),
            "fill_ms_median": statistics.median(r["fill_ms"] for r in rows)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", default="2")
    ap.add_argument("--windows", type=int, default=4)
    ap.add_argument("--window", type=float, default=10.0, help="seconds per window")
    ap.add_argument("--chromium", default=CHROMIUM)
    args = ap.parse_args()
    sys.stdout.write(json.dumps(measure(args.speed, args.windows, args.window, args.chromium), indent=1) + "\n")


if __name__ == "__main__":  # the server's runs start processes: guard the module's start
    main()
