"""Faults from the dashboard (issue 14, part 2), in a real browser on a real server and closed loop:
the fault panel injects a TC2 dropout into a running run, the panel lists it in force, and the twin's
detection shows up in the panel and the event log; "Clear faults" empties the list in force.  The
header says the radiation model is ready; each run links to the rerun web viewer when one runs (not here).
Screenshot: test-artifacts/dashboard-faults.png."""

from __future__ import annotations

import httpx
import pytest
from test_browser import _wait_text

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from conftest import wait_model_ready

pytestmark = pytest.mark.browser

LIVE_RUN = {"duration": 600.0, "speed": 2.0, "reference": {"setpoint": 900.0, "t_E": 8.0}}  # as test_browser.py


def test_inject_and_clear_a_fault_from_the_dashboard(tmp_path, small_cfg, browser, artifacts) -> None:
    s = Settings(data_dir=tmp_path, viser_port=0)
    with ThreadedServer(create_app(s, small_cfg), free_port()) as srv:
        with httpx.Client(base_url=srv.url, timeout=60) as c:
            wait_model_ready(c)  # so the POST's own checks run now, not once the run waits as queued
            r = c.post("/api/runs", json=LIVE_RUN)
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(srv.url)
        _wait_text(page, "#server-state", "server ok")
        assert "radiation model" not in page.inner_text("#server-state")  # ready: nothing to say
        _wait_text(page, "#run-badge", "running")
        # the kinds follow the target: a lamp group has failed / derate, a TC the four TC kinds
        page.select_option("#fault-target", "T2v")
        assert page.eval_on_selector_all("#fault-kind option", "os => os.map(o => o.value)") == ["failed", "derate"]
        page.select_option("#fault-target", "TC2")
        page.select_option("#fault-kind", "dropout")
        assert page.is_disabled("#fault-value")
        assert page.is_disabled("#fault-inject")  # nothing in the list yet
        page.click("#fault-add")
        _wait_text(page, "#fault-pending", "TC2 dropout")
        page.click("#fault-inject")
        _wait_text(page, "#fault-msg", "applied")
        _wait_text(page, "#fault-force", "TC2 dropout")
        _wait_text(page, "#fault-found", "TC2", timeout=60_000)  # the twin's reading test: no reading for 0.5 s
        assert "dropout" in page.inner_text("#fault-found")
        _wait_text(page, "#event-log", "fault detected: TC2")
        page.screenshot(path=str(artifacts / "dashboard-faults.png"))
        page.click("#fault-clear")
        _wait_text(page, "#fault-msg", "clear the faults: applied")
        _wait_text(page, "#fault-force", "none")
        httpx.post(f"{srv.url}/api/runs/{run_id}/stop", timeout=30)
        page.close()
        assert not errors, errors
