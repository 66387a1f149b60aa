"""A real browser (Debian chromium via playwright) on a real server (uvicorn on loopback) with the
real closed loop: the dashboard starts a run with a points reference, the heat map and charts
update, oscillation is toggled and the reference changed live (replies on the message line,
streamed events in the event log); the viser page draws the plate; a token-protected server asks
for its token.  Each test starts (and stops) the runs it needs.  Screenshots: test-artifacts/."""

from __future__ import annotations

import time

import httpx
import numpy as np
import pytest

from backend.app import create_app
from backend.settings import Settings
from backend.threaded_server import ThreadedServer, free_port
from conftest import fake_factory

pytestmark = pytest.mark.browser

LIVE_RUN = {"duration": 600.0, "speed": 2.0, "reference": {"setpoint": 900.0, "t_E": 8.0}}


@pytest.fixture(scope="module")
def server(tmp_path_factory, small_cfg):
    s = Settings(data_dir=tmp_path_factory.mktemp("browser"), viser_port=free_port())
    with ThreadedServer(create_app(s, small_cfg, viser=True), free_port()) as srv:
        srv.viser_url = f"http://127.0.0.1:{s.viser_port}/"
        yield srv


def _js(page, expr: str):
    return page.evaluate(expr)


def _text(page, selector: str) -> str:
    return page.inner_text(selector)


def _open_dashboard(browser, url: str):
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    errors: list[str] = []
    # a refused request (401 / 422) is logged by chromium as a failed resource: expected here
    page.on("console", lambda m: errors.append(m.text)
            if m.type == "error" and "Failed to load resource" not in m.text else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_function("document.getElementById('server-state').textContent.startsWith('server ok')")
    return page, errors


def _wait_text(page, selector: str, needle: str, timeout: float = 90_000) -> None:
    """Wait until the element's text contains ``needle``; on timeout say what it showed."""
    try:
        page.wait_for_function("([s, n]) => document.querySelector(s).textContent.includes(n)",
                               arg=[selector, needle], timeout=timeout)
    except Exception as exc:
        raise AssertionError(f"{selector} never showed {needle!r}: {_text(page, selector)!r}") from exc


def _events(page) -> list[str]:
    return _js(page, "[...document.querySelectorAll('#event-log li:not(.empty)')].map((li) => li.textContent)")


def test_dashboard_points_run_with_live_changes(server, browser, artifacts, small_cfg) -> None:
    page, errors = _open_dashboard(browser, server.url)
    n_runs = len(httpx.get(f"{server.url}/api/runs", timeout=10).json())
    page.check("input[name=refmode][value=points]")
    assert page.is_visible("textarea[name=points]") and not page.is_visible("input[name=setpoint]")
    # a bad line is caught in the browser, with its line number; nothing is started
    page.fill("textarea[name=points]", "4, 700\n8 degrees, 900")
    page.click("#start-btn")
    _wait_text(page, "#start-msg", "line 2")
    assert "time, temperature" in _text(page, "#start-msg")
    assert len(httpx.get(f"{server.url}/api/runs", timeout=10).json()) == n_runs
    # a points reference: the loop starts from the initial mean at t = 0, 700 K at 4 s, 900 K from 8 s on
    page.fill("textarea[name=points]", "4, 700\n8, 900")
    page.fill("input[name=duration]", "600")
    page.fill("input[name=speed]", "2")
    page.click("#start-btn")
    _wait_text(page, "#start-msg", "started: reference points 4 s → 700 K, 8 s → 900 K")
    run_id = _js(page, "state.runId")
    run = httpx.get(f"{server.url}/api/runs/{run_id}", timeout=10).json()
    assert run["scenario"]["reference"] == {"points": [[4.0, 700.0], [8.0, 900.0]]}
    # charts fill from the live stream; T_ref follows the points, which are marked on the chart
    page.wait_for_function("document.getElementById('mean-plot').data[0].x.slice(-1)[0] > 9", timeout=120_000)
    heat = _js(page, "document.getElementById('heatmap').data[0].z")
    assert len(heat) == small_cfg.specimen.ny and len(heat[0]) == small_cfg.specimen.nx
    assert all(v is not None for row in heat for v in row)
    t_ref = _js(page, "(() => { const d = document.getElementById('mean-plot').data[0];"
                      " return d.x.map((t, k) => [t, d.y[k]]); })()")
    assert abs(min(t_ref, key=lambda p: abs(p[0] - 4.0))[1] - 700.0) < 1.0
    assert all(abs(T - 900.0) < 0.5 for t, T in t_ref if t >= 8.0)
    assert _js(page, "document.getElementById('mean-plot').data[2].x") == [4.0, 8.0]
    t1 = _js(page, "document.getElementById('mean-plot').data[1].x.slice(-1)[0]")
    time.sleep(1.5)
    assert _js(page, "document.getElementById('mean-plot').data[1].x.slice(-1)[0]") > t1  # still updating

    # oscillation on: the reply stays on the message line while the loop's events go to the event log
    page.click("#osc-btn")
    _wait_text(page, "#ctl-msg", "oscillation on: applied at t =")
    reply = _text(page, "#ctl-msg")
    _wait_text(page, "#event-log", "re-planned")  # the re-plan ends after the reply
    assert any(e.startswith("t = ") and "oscillation on at t =" in e for e in _events(page)), _events(page)
    assert _text(page, "#ctl-msg") == reply  # not overwritten by the streamed events
    assert _text(page, "#osc-btn") == "Oscillation off"
    page.wait_for_function(
        "Math.max(...document.getElementById('eta-plot').data[0].y.map(Math.abs)) > 5", timeout=60_000)

    # live reference by points (times from now): a bad line, an unreachable point (server 422), a good one
    page.check("input[name=live-refmode][value=points]")
    page.fill("#new-points", "3; 950; 1")
    page.click("#ref-btn")
    _wait_text(page, "#ctl-msg", "line 1")
    page.fill("#new-points", "3, 260")
    page.click("#ref-btn")
    _wait_text(page, "#ctl-msg", "refused: 422")
    assert "260.0 K is unreachable" in _text(page, "#ctl-msg")
    page.fill("#new-points", "3, 950\n6, 1000")
    page.click("#ref-btn")
    _wait_text(page, "#ctl-msg", "reference points 3 s → 950 K, 6 s → 1000 K (times from now): applied at t =")
    _wait_text(page, "#event-log", "reference changed at t =")
    assert "applied" in _text(page, "#ctl-msg")
    page.wait_for_function("document.getElementById('mean-plot').data[2].x.length === 4", timeout=30_000)
    applied_t = next(ch["applied_t"] for ch in httpx.get(f"{server.url}/api/runs/{run_id}", timeout=10).json()
                     ["changes"] if ch["kind"] == "reference" and ch["status"] == "applied")
    markers = _js(page, "document.getElementById('mean-plot').data[2].x")
    assert markers[2:] == pytest.approx([applied_t + 3.0, applied_t + 6.0])
    # the reply, the loop's event and the markers agree on when the new points start
    assert f"applied at t = {applied_t:.1f} s" in _text(page, "#ctl-msg")
    assert any(f"reference changed at t = {applied_t:.1f} s" in e for e in _events(page)), _events(page)
    page.wait_for_function("document.getElementById('mean-plot').data[0].y.slice(-1)[0] > 999", timeout=90_000)
    # powers, TC errors and inhomogeneity are drawn as well
    assert _js(page, "document.getElementById('power-plot').data.length") == 12  # 6 groups x (u, u_ff)
    assert _js(page, "document.getElementById('tc-plot').data[3].y.length") > 10
    assert _js(page, "document.getElementById('inh-plot').data[0].y.length") > 10
    assert len(_events(page)) <= 200  # the log is bounded
    page.screenshot(path=str(artifacts / "dashboard.png"), timeout=120_000)

    page.click("#stop-btn")
    _wait_text(page, "#ctl-msg", "; its data is kept", timeout=60_000)
    assert _events(page)[0].endswith("run stopped")  # newest at top
    assert not errors, errors
    page.close()


def test_viser_follows_a_run_then_stop_from_dashboard(server, browser, artifacts) -> None:
    """The 3D view follows the run and draws the plate; the dashboard's Stop ends the run and its
    data stays.  The screenshot is taken after the stop: a still scene renders in a few seconds in
    software WebGL, a live one (5 updates/s) takes 10-40 s per screenshot on a loaded machine."""
    from PIL import Image

    r = httpx.post(f"{server.url}/api/runs", json=LIVE_RUN, timeout=60)
    assert r.status_code == 201, r.text
    run_id = r.json()["id"]
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(server.viser_url)
    page.wait_for_selector("canvas", timeout=60_000)
    page.wait_for_selector("text=T_ref", timeout=120_000)
    page.wait_for_selector(f"text={run_id}", timeout=60_000)  # the status names the followed run
    time.sleep(2.0)  # a few scene updates of the running run

    dash, errors = _open_dashboard(browser, server.url)
    dash.wait_for_selector(f"#history tr[data-id='{run_id}']", timeout=30_000)
    dash.click(f"#history tr[data-id='{run_id}'] td:first-child")
    dash.wait_for_function("document.getElementById('run-badge').textContent === 'running'", timeout=60_000)
    assert _js(dash, "state.runId") == run_id
    dash.click("#stop-btn")
    dash.wait_for_function("document.getElementById('run-badge').textContent === 'stopped'", timeout=60_000)
    run = httpx.get(f"{server.url}/api/runs/{run_id}", timeout=10).json()
    assert run["status"] == "stopped" and run["files"]["timeseries"] and run["files"]["recording"]
    assert 0.0 < run["latest"]["t"] < 600.0  # stopped before the 600 s duration
    assert not errors, errors
    dash.close()

    page.bring_to_front()
    page.wait_for_selector("text=· stopped", timeout=60_000)  # the 3D view's status follows the run's end
    path = artifacts / "viser.png"
    page.screenshot(path=str(path), timeout=180_000)
    # left: the axes gizmo (bottom-left corner); right: the GUI panel with its blue buttons
    img = np.asarray(Image.open(path).convert("RGB")).astype(int)[:, 100:900]
    r_, g, b = img[..., 0], img[..., 1], img[..., 2]
    # the plate's turbo colours span its own min..max, so its hottest part is dark red/orange once a
    # run is shown; nothing else in the scene (gold, grey, yellow lamps, white, light-blue window)
    # is red.  Before any run the uniform plate is green and the count is 0 (measured); a drawn
    # run plate gives thousands (measured 2400-4300), partly hidden by the lamps.
    red = np.sum((r_ > 140) & (g < 110) & (b < 80))
    assert red > 500, red
    page.close()


def test_dashboard_asks_for_the_token(browser, tmp_path, small_cfg, artifacts) -> None:
    """With FURNACE_TWIN_API_TOKEN set the dashboard shows a token field; a start without it gets a
    message that says where to enter it; the token is kept for the tab only (never in the URL)."""
    s = Settings(data_dir=tmp_path / "data", viser_port=0, api_token="s3cret-token-0123456")
    with ThreadedServer(create_app(s, small_cfg, loop_factory=fake_factory()), free_port()) as srv:
        page, errors = _open_dashboard(browser, srv.url)
        page.wait_for_selector("#token-box", state="visible")
        page.fill("input[name=duration]", "600")
        page.fill("input[name=speed]", "1")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", "401: this server needs its API token")
        assert "API token" in _text(page, "#start-msg") and "s3cret" not in page.content()
        assert _js(page, "document.getElementById('token').classList.contains('need')")
        page.screenshot(path=str(artifacts / "dashboard-token.png"))
        page.fill("#token", "wrong")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", "401: the API token is wrong")
        page.fill("#token", "s3cret-token-0123456")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", "started")
        run_id = _js(page, "state.runId")
        page.wait_for_function("document.getElementById('run-badge').textContent === 'running'", timeout=30_000)
        assert _js(page, "sessionStorage.getItem('furnace-twin-token')") == "s3cret-token-0123456"
        assert _js(page, "localStorage.getItem('furnace-twin-token')") is None
        assert "s3cret" not in page.url
        page.click("#stop-btn")  # a mutating request with the token from the field
        _wait_text(page, "#ctl-msg", "; its data is kept", timeout=30_000)
        assert httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()["status"] == "stopped"
        assert not errors, errors
        page.close()


def test_inputs_come_from_the_furnace(browser, tmp_path, artifacts) -> None:
    """On a furnace whose eta_max (30 mm) is below the paper's 3 L_h = 48 mm, the amplitude inputs stop at
    30 mm and start there; a start leaving it as shown runs with 30 mm; a live amplitude above it gets the
    server's 422 on the message line, and the live inputs show what the server says the run uses."""
    from twin.config import load_config
    from twin.limits import furnace_name

    path = tmp_path / "low_stroke.toml"
    path.write_text('base = "default"\n[oscillation]\neta_max = 0.03\n')
    cfg = load_config(path)
    s = Settings(data_dir=tmp_path / "data", viser_port=0, max_duration_s=900.0)
    app = create_app(s, cfg, loop_factory=fake_factory(), furnace_name=furnace_name(cfg, path))
    with ThreadedServer(app, free_port()) as srv:
        page, errors = _open_dashboard(browser, srv.url)
        bounds = _js(page, "['amplitude', 'duration'].map((n) => { const e = document.querySelector("
                           "`#start-form [name=${n}]`); return [e.min, e.max, e.value]; })")
        assert bounds == [["0", "0.03", "0.03"], ["1", "900", "240"]]
        assert _js(page, "document.getElementById('live-amplitude').max") == "0.03"
        assert "furnace low_stroke · η ≤ 30 mm" in _text(page, "header")
        page.check("input[name=osc]")
        page.fill("input[name=speed]", "1")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", "started")
        run_id = _js(page, "state.runId")
        run = httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()
        assert run["oscillation"] == {"enabled": True, "amplitude": 0.03, "period": 18.0}
        _wait_text(page, "#osc-btn", "Oscillation off")  # the run oscillates: the server says so
        page.fill("#live-amplitude", "0.04")
        page.click("#osc-btn")
        _wait_text(page, "#ctl-msg", "422")
        assert "amplitude: at most 0.03 m (eta_max of furnace 'low_stroke'), got 0.04 m" in _text(page, "#ctl-msg")
        page.fill("#live-amplitude", "0.02")
        page.click("#osc-btn")  # off, with the amplitude typed
        _wait_text(page, "#ctl-msg", "oscillation off: applied")
        _wait_text(page, "#osc-btn", "Oscillation on")
        page.screenshot(path=str(artifacts / "dashboard-low-stroke.png"))
        after = httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()
        assert after["oscillation"] == {"enabled": False, "amplitude": 0.02, "period": 18.0}
        page.click("#stop-btn")
        _wait_text(page, "#ctl-msg", "; its data is kept", timeout=30_000)
        assert not errors, errors
        page.close()
