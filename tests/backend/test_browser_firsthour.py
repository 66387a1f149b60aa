"""The first hour of a lab user (issue 27), in chromium on a real server with the real closed loop (small furnace).

A page samples what it shows every 50 ms (run id and status, whether the heat map has values, the clock, whether
the live-change buttons are enabled), so the test sees the moments between a start and the first frame, and a
run's end, that a screenshot would miss.  Screenshots go to
test-artifacts/.
"""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import pytest

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from conftest import open_dashboard, wait_model_ready

pytestmark = pytest.mark.browser


#: every 50 ms: what the page shows of the selected run (window.seen, newest last)
WATCH = """
window.seen = [];
setInterval(() => {
  const z = (document.getElementById('heatmap').data || [{}])[0].z || [[null]];
  window.seen.push({ id: state.runId, status: state.run ? state.run.status : null, frame: !!state.lastFrame,
    heat: z.some((row) => row.some((v) => v !== null)), clock: document.getElementById('run-clock').textContent,
    sub: document.getElementById('heat-sub').textContent,
    ref: !document.getElementById('ref-btn').disabled, osc: !document.getElementById('osc-btn').disabled });
}, 50);
"""


@pytest.fixture(scope="module")
def server(tmp_path_factory, small_cfg):
    s = Settings(data_dir=tmp_path_factory.mktemp("firsthour"), change_timeout_s=120.0)
    with ThreadedServer(create_app(s, small_cfg), free_port()) as srv:
        with httpx.Client(base_url=srv.url, timeout=10) as c:
            wait_model_ready(c)
        yield srv


def _screenshot(page, artifacts: Path, name: str) -> None:
    path = artifacts / name
    page.screenshot(path=str(path), timeout=120_000)


def _start(page, setpoint: float, t_E: float, duration: float, speed: str) -> str:
    page.check("input[name=refmode][value=transition]")
    page.fill("input[name=setpoint]", str(setpoint))
    page.fill("input[name=t_E]", str(t_E))
    page.fill("input[name=duration]", str(duration))
    page.fill("input[name=speed]", speed)
    before = page.evaluate("state.runId")
    page.click("#start-btn")
    page.wait_for_function("([b]) => state.runId && state.runId !== b", arg=[before], timeout=60_000)
    return str(page.evaluate("state.runId"))


def test_a_new_run_starts_empty_and_takes_changes_once_it_runs(server, browser, artifacts) -> None:
    page, errors = open_dashboard(browser, server.url, 1400, 900)
    page.evaluate(WATCH)
    # a first run, at speed max: its charts must not blank when it ends
    first = _start(page, 700.0, 20.0, 30.0, "max")
    page.wait_for_function("state.run && ['finished', 'error'].includes(state.run.status) && !state.loading",
                           timeout=180_000)
    page.wait_for_timeout(1000)
    assert page.evaluate("state.run.status") == "finished", page.evaluate("state.run")
    seen = page.evaluate("window.seen")
    mine = [s for s in seen if s["id"] == first]
    had = next(k for k, s in enumerate(mine) if s["heat"])
    blank = [s for s in mine[had:] if not s["heat"]]
    assert not blank, f"the heat map blanked {len(blank)} times after the run's first frame: {blank[:3]}"
    assert page.evaluate("document.getElementById('run-clock').textContent").startswith("t = 30")
    # the heat map's colours span the fillet (issue 27: the cold edges made the fillet one flat colour)
    zmin, zmax, lowest = page.evaluate("(() => { const d = document.getElementById('heatmap').data[0];"
                                       " return [d.zmin, d.zmax, Math.min(...d.z.flat())]; })()")
    assert zmin - lowest > 50 and zmax - zmin < 100, (zmin, zmax, lowest)
    _screenshot(page, artifacts, "firsthour-heatmap-fillet.png")

    # the second run: empty until its first frame, changes refused (disabled) until it runs
    page.evaluate("window.seen = []")
    second = _start(page, 900.0, 30.0, 600.0, "1")
    shot = False
    end = time.monotonic() + 180
    while not page.evaluate("state.run && state.run.id === state.runId && state.lastFrame !== null"):
        if not shot and page.evaluate("state.run && state.run.id === state.runId && !state.lastFrame"):
            _screenshot(page, artifacts, "firsthour-new-run-planning.png")
            shot = True
        assert time.monotonic() < end, "the second run never showed a frame"
        page.wait_for_timeout(50)
    page.wait_for_function("!document.getElementById('ref-btn').disabled", timeout=60_000)
    seen = page.evaluate("window.seen")
    mine = [s for s in seen if s["id"] == second]
    before_frame = [s for s in mine if not s["frame"]]
    assert before_frame, "the page never showed the second run before its first frame"
    # nothing of the first run: no heat map, no clock, and the live changes disabled
    assert not any(s["heat"] for s in before_frame), [s for s in before_frame if s["heat"]][:3]
    assert not any(s["clock"] for s in before_frame), [s["clock"] for s in before_frame if s["clock"]][:3]
    assert not any(s["ref"] or s["osc"] for s in before_frame if s["status"] != "running")
    assert any(s["status"] in ("queued", "starting") for s in before_frame), {s["status"] for s in before_frame}
    # the heat map says what the run waits for (within one redraw, 250 ms, of the status arriving)
    starting = [s["sub"] for s in before_frame if s["status"] == "starting"]
    assert "planning the first trajectory …" in starting, set(starting)
    k = starting.index("planning the first trajectory …")
    assert k <= 6 and set(starting[k:]) == {"planning the first trajectory …"}, starting
    assert shot
    # the server says the same: a change before the first sample is refused, after it checked like a start
    run = httpx.get(f"{server.url}/api/runs/{second}", timeout=10).json()
    assert run["status"] == "running" and run["latest"] is not None
    far = httpx.put(f"{server.url}/api/runs/{second}/reference", json={"setpoint": 1250.0, "t_E": 2.0}, timeout=120)
    assert far.status_code == 422 and "cannot follow" in far.text, far.text
    httpx.post(f"{server.url}/api/runs/{second}/stop", timeout=30)
    page.wait_for_function("state.run && state.run.status === 'stopped'", timeout=120_000)
    assert not errors, errors
    page.close()


def test_the_events_tell_what_happened_with_a_severity_filter(server, browser, artifacts) -> None:
    """A heat-up with a live reference change: the list reads as what happened (start, change, end first; lamp
    groups only for a spell that mattered, in plain words); the filter narrows it; the report lists every
    change and warning."""
    page, errors = open_dashboard(browser, server.url, 1400, 900)
    run_id = _start(page, 800.0, 20.0, 120.0, "5")
    page.wait_for_function("state.run && state.run.status === 'running' && !document.getElementById('ref-btn')"
                           ".disabled", timeout=180_000)
    page.check("input[name=live-refmode][value=transition]")
    page.fill("#new-setpoint", "1000")
    page.fill("#new-tE", "20")
    page.click("#ref-btn")
    page.wait_for_function("document.getElementById('ctl-msg').textContent.includes('applied at t =')",
                           timeout=120_000)
    page.wait_for_function("state.run && state.run.status === 'finished' && !state.loading", timeout=240_000)
    # the end is stored after the stream closed (and maybe after the page read the history): it must still show
    page.wait_for_function("(document.querySelector('#event-log li') || {}).textContent.endsWith('run finished')",
                           timeout=30_000)
    page.wait_for_timeout(500)
    texts = page.evaluate("[...document.querySelectorAll('#event-log li:not(.empty)')].map((li) => li.textContent)")
    every = httpx.get(f"{server.url}/api/runs/{run_id}/series", timeout=30).json()["events"]
    missing = [e for e in every if not any(t.endswith(e["text"]) for t in texts)]
    assert len(texts) == len(every) > 2, f"the page lacks {missing}"
    assert texts[-1].endswith(every[0]["text"]) and every[0]["kind"] == "run_started"
    assert every[-1]["kind"] == "run_ended" and every[-1]["text"] == "run finished"
    assert not [e for e in every if "no headroom left to cool" in e["text"] or "off (0 %)" in e["text"]]
    for e in every:
        if e["kind"] == "saturation":  # a spell that mattered says its effect
            assert "the fillet mean" in e["text"], e
    assert not any("cannot explain the TCs" in e["text"] for e in every)
    _screenshot(page, artifacts, "firsthour-events-all.png")

    page.select_option("#event-filter", "changes")
    changes = page.evaluate("[...document.querySelectorAll('#event-log li:not(.empty)')].map((li) => li.textContent)")
    assert any("reference changed at t =" in t for t in changes), changes
    assert any(t.endswith("run finished") for t in changes) and any("run started" in t for t in changes)
    assert len(changes) < len(texts) or all(e["level"] != "info" for e in every[1:-1])
    page.select_option("#event-filter", "warn")
    warned = page.evaluate("[...document.querySelectorAll('#event-log li:not(.empty)')].map((li) => li.className)")
    assert all(c in ("warn", "error") for c in warned), warned
    assert len(warned) == sum(e["level"] in ("warn", "error") for e in every)
    page.select_option("#event-filter", "all")

    report = httpx.get(f"{server.url}/api/runs/{run_id}/report.png", timeout=120)
    assert report.status_code == 200
    (artifacts / "firsthour-report.png").write_bytes(report.content)
    assert not errors, errors
    page.close()
