"""A real browser (Debian chromium via playwright) on a real server (uvicorn on loopback) with the
real closed loop: the dashboard starts a run with a points reference, the heat map and charts
update, oscillation is toggled and the reference changed live (replies on the message line,
streamed events in the event log); the viser page draws the plate; a token-protected server asks
for its token.  Each test starts (and stops) the runs it needs.  Screenshots: test-artifacts/."""

from __future__ import annotations

import socket
import time

import httpx
import numpy as np
import pytest

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from conftest import FakeFactory, fake_factory, open_dashboard

pytestmark = pytest.mark.browser

LIVE_RUN = {"duration": 600.0, "speed": 2.0, "reference": {"setpoint": 900.0, "t_E": 8.0}}


@pytest.fixture(scope="module")
def server(tmp_path_factory, small_cfg):
    s = Settings(data_dir=tmp_path_factory.mktemp("browser"), viser_port=free_port(), change_timeout_s=120.0)
    with ThreadedServer(create_app(s, small_cfg, viser=True), free_port()) as srv:
        srv.viser_url = f"http://127.0.0.1:{s.viser_port}/"
        yield srv


def _js(page, expr: str):
    return page.evaluate(expr)


def _text(page, selector: str) -> str:
    return page.inner_text(selector)


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
    page, errors = open_dashboard(browser, server.url)
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
    _wait_text(page, "#start-msg", ": reference points 4 s → 700 K, 8 s → 900 K")
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
    assert all(abs(T - 900.0) < 0.5 for t, T in t_ref if t >= 8.0)
    # at 4 s exactly, from the run's series (the chart may miss a streamed sample on a loaded machine)
    stored = httpx.get(f"{server.url}/api/runs/{run_id}/series", params={"max_points": 20000}, timeout=30).json()
    k = min(range(len(stored["t"])), key=lambda i: abs(stored["t"][i] - 4.0))
    assert stored["t"][k] == pytest.approx(4.0) and abs(stored["T_ref"][k] - 700.0) < 1.0
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
    page.wait_for_function(  # eta (mm) is the power chart's last trace, on its lower axis
        "Math.max(...document.getElementById('power-plot').data[12].y.map(Math.abs)) > 5", timeout=60_000)

    # live reference by points (times from now): a bad line, an unreachable point (server 422), a good one
    page.check("input[name=live-refmode][value=points]")
    page.fill("#new-points", "3; 950; 1")
    page.click("#ref-btn")
    _wait_text(page, "#ctl-msg", "line 1")
    page.fill("#new-points", "3, 260")  # below the furnace's range: the page says so with the server's limits
    page.click("#ref-btn")
    _wait_text(page, "#ctl-msg", "260 K is outside 300")
    page.fill("#new-points", "0.5, 1250")  # within the range, far beyond what the lamps can do: the server's 422
    page.click("#ref-btn")
    _wait_text(page, "#ctl-msg", "refused: this furnace cannot follow the new reference")
    assert "K short" in _text(page, "#ctl-msg")
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
    assert _js(page, "document.getElementById('power-plot').data.length") == 13  # 6 groups x (u, u_ff), eta
    assert _js(page, "document.getElementById('tc-plot').data[3].y.length") > 10
    assert _js(page, "document.getElementById('inh-plot').data[0].y.length") > 10
    assert len(_events(page)) <= 200  # the log is bounded
    page.screenshot(path=str(artifacts / "dashboard.png"), timeout=120_000)

    page.click("#stop-btn")
    _wait_text(page, "#ctl-msg", "; its data is kept")  # finalising: up to 90 s on a loaded machine
    page.wait_for_function("document.querySelector('#event-log li').textContent.includes('run stopped at t =')")
    assert "run stopped at t =" in _events(page)[0]  # newest at top
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

    dash, errors = open_dashboard(browser, server.url)
    dash.wait_for_selector(f"#run-pick option[value='{run_id}']", state="attached", timeout=30_000)
    dash.select_option("#run-pick", run_id)
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
    page.wait_for_selector("text=· stopped", timeout=180_000)  # the 3D view's status follows the run's end
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
        page, errors = open_dashboard(browser, srv.url)
        page.wait_for_selector("#token-box", state="visible")
        page.fill("input[name=duration]", "600")
        page.fill("input[name=speed]", "1")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", "this server needs its API token")
        assert "API token" in _text(page, "#start-msg") and "s3cret" not in page.content()
        assert _js(page, "document.getElementById('token').classList.contains('need')")
        page.screenshot(path=str(artifacts / "dashboard-token.png"))
        page.fill("#token", "wrong")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", "the API token is wrong")
        page.fill("#token", "s3cret-token-0123456")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", ": reference")
        run_id = _js(page, "state.runId")
        page.wait_for_function("document.getElementById('run-badge').textContent === 'running'", timeout=30_000)
        assert _js(page, "sessionStorage.getItem('furnace-twin-token')") == "s3cret-token-0123456"
        assert _js(page, "localStorage.getItem('furnace-twin-token')") is None
        assert "s3cret" not in page.url
        page.click("#stop-btn")  # a mutating request with the token from the field
        _wait_text(page, "#ctl-msg", "; its data is kept")  # finalising: up to 90 s on a loaded machine
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
    s = Settings(data_dir=tmp_path / "data", viser_port=0, max_duration_s=900.0, change_timeout_s=120.0)
    app = create_app(s, cfg, loop_factory=fake_factory(), furnace_name=furnace_name(cfg, path))
    with ThreadedServer(app, free_port()) as srv:
        page, errors = open_dashboard(browser, srv.url)
        bounds = _js(page, "['amplitude', 'duration'].map((n) => { const e = document.querySelector("
                           "`#start-form [name=${n}]`); return [e.min, e.max, e.value]; })")
        assert bounds == [["0", "0.03", "0.03"], ["0", "900", "240"]]  # duration: above 0 (data-open)
        assert _js(page, "document.getElementById('live-amplitude').max") == "0.03"
        assert "furnace low_stroke · η ≤ 30 mm" in _text(page, "header")
        # the truth choice: independent (the furnace file's [truth]) by default, shared to compare
        assert _js(page, "[...document.querySelector('#start-form [name=truth]').options].map((o) => o.value)") \
            == ["independent", "shared"]
        assert _js(page, "document.querySelector('#start-form [name=truth]').value") == "independent"
        page.select_option("#start-form [name=truth]", "shared")
        page.check("input[name=osc]")
        page.fill("input[name=speed]", "1")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", ": reference")
        run_id = _js(page, "state.runId")
        run = httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()
        assert run["oscillation"] == {"enabled": True, "amplitude": 0.03, "period": 18.0}
        assert run["scenario"]["truth"] == "shared"
        _wait_text(page, "#osc-btn", "Oscillation off")  # the run oscillates: the server says so
        page.fill("#live-amplitude", "0.04")  # the page checks with the furnace's limits, the server's own
        page.click("#osc-btn")
        _wait_text(page, "#ctl-msg", "Amplitude: must be at most 0.03 m, got 0.04 m")
        body = {"enabled": False, "amplitude": 0.04, "period": 18.0}  # what the server says to a direct request
        r = httpx.put(f"{srv.url}/api/runs/{run_id}/oscillation", json=body, timeout=10)
        assert r.status_code == 422 and "at most 0.03 m (eta_max of furnace 'low_stroke'), got 0.04 m" in r.text
        page.fill("#live-amplitude", "0.02")
        page.click("#osc-btn")  # off, with the amplitude typed
        _wait_text(page, "#ctl-msg", "oscillation off: applied")
        _wait_text(page, "#osc-btn", "Oscillation on")
        page.screenshot(path=str(artifacts / "dashboard-low-stroke.png"))
        after = httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()
        assert after["oscillation"] == {"enabled": False, "amplitude": 0.02, "period": 18.0}
        page.click("#stop-btn")
        _wait_text(page, "#ctl-msg", "; its data is kept")  # finalising: up to 90 s on a loaded machine
        assert not errors, errors
        page.close()


def test_dashboard_starts_an_opcua_run_only_where_allowed(server, browser, artifacts) -> None:
    """The form's furnace choice: OPC UA shows the endpoint and hides what only a simulation has (speed,
    noise, seed, deviations); an endpoint the server may not, or cannot, reach is refused on the message line."""
    page, errors = open_dashboard(browser, server.url)
    n_runs = len(httpx.get(f"{server.url}/api/runs", timeout=10).json())
    assert not page.is_visible("input[name=endpoint]") and page.is_visible("input[name=speed]")
    page.check("input[name=plant][value=opcua]")
    assert page.is_visible("input[name=endpoint]")
    for hidden in ("speed", "tc_noise", "seed", "m_eps"):
        assert not page.is_visible(f"input[name={hidden}]"), hidden
    # a furnace over OPC UA has no truth (issue 10's choice applies to the simulation only)
    assert not page.is_visible("select[name=truth]") and not page.is_visible("details.more")
    body = _js(page, "import('/assets/forms.js').then((m) => m.scenarioFromForm())")
    assert body["plant"]["kind"] == "opcua" and not {"truth", "speed", "seed", "tc_noise", "mismatch"} & set(body)
    page.fill("input[name=endpoint]", "opc.tcp://10.9.9.9:4840/furnace-twin/")
    page.click("#start-btn")
    _wait_text(page, "#start-msg", "FURNACE_TWIN_OPCUA_ENDPOINTS")
    assert _js(page, "document.getElementById('start-msg').className") == "msg err"  # the 422's sentence
    # the feasibility preview (POST /api/feasibility) refuses the same endpoint before any start
    _wait_text(page, "#feasibility", "FURNACE_TWIN_OPCUA_ENDPOINTS")
    with socket.socket() as s:  # bound, not listening: nothing answers there
        s.bind(("127.0.0.1", 0))
        page.fill("input[name=endpoint]", f"opc.tcp://127.0.0.1:{s.getsockname()[1]}/furnace-twin/")
        page.click("#start-btn")
        _wait_text(page, "#start-msg", "connection refused")
    page.screenshot(path=str(artifacts / "dashboard-opcua-refused.png"))
    assert len(httpx.get(f"{server.url}/api/runs", timeout=10).json()) == n_runs  # nothing was started
    page.check("input[name=plant][value=simulated]")
    assert page.is_visible("input[name=speed]") and not page.is_visible("input[name=endpoint]")
    assert page.is_visible("select[name=truth]") and page.is_visible("details.more")
    assert not errors, errors
    page.close()


# ---- the dashboard for daily use (issue 16): history on reload, comparison, double click ----
def _fake_server(tmp_path, cfg, factory=None):
    s = Settings(data_dir=tmp_path / "data", viser_port=0)
    return ThreadedServer(create_app(s, cfg, loop_factory=factory or fake_factory()), free_port())


def _event_texts(page) -> list[str]:
    return _js(page, "[...state.events.values()].sort((a, b) => a.n - b.n).map((e) => e.text)")


def test_reload_shows_the_whole_history_and_every_tab_the_same_events(browser, tmp_path, small_cfg,
                                                                      artifacts) -> None:
    with _fake_server(tmp_path, small_cfg) as srv:
        run_id = httpx.post(f"{srv.url}/api/runs", json={**LIVE_RUN, "speed": 2.0}, timeout=30).json()["id"]
        first, errors = open_dashboard(browser, srv.url)  # shows the newest running run
        first.wait_for_function("state.runId !== null && state.series.t.length > 5", timeout=60_000)
        deadline = time.monotonic() + 60
        # the run's `latest` is stored at its first flush: null until then, while the page streams already
        while (httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()["latest"] or {}).get("t", 0.0) < 3.0:
            assert time.monotonic() < deadline
            time.sleep(0.2)
        change = httpx.put(f"{srv.url}/api/runs/{run_id}/reference", json={"setpoint": 950.0, "t_E": 4.0},
                           timeout=30)
        assert change.status_code == 200
        first.wait_for_function("state.series.t.slice(-1)[0] > 8", timeout=60_000)
        # a second tab, and the first one reloaded: each shows the run from its first sample on
        t_before = httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()["latest"]["t"]
        second, errors2 = open_dashboard(browser, srv.url)
        first.reload()
        first.wait_for_function("document.getElementById('server-state').textContent.startsWith('server ok')")
        for page in (first, second):
            page.wait_for_function("state.runId !== null && !state.loading && document.getElementById('mean-plot')"
                                   ".data[1].x.length > 50", timeout=60_000)
            xs = _js(page, "document.getElementById('mean-plot').data[1].x")
            end = _js(page, "state.historyEnd")
            # the history: every sample from the first one to where the live run was when the page asked
            # (fresher than the last flush); the stream continues after it
            assert xs[0] == pytest.approx(0.1) and end >= t_before and xs[-1] > end
            history = [x for x in xs if x <= end + 1e-9]
            assert len(history) == round(end / 0.1) and max(np.diff(history)) < 0.15
        time.sleep(1.0)
        a, b = _event_texts(first), _event_texts(second)
        assert a == b and len(set(a)) == len(a), (a, b)  # the same events, each once
        assert a[0].startswith("run started") and any("reference changed" in e for e in a)
        assert len(_events(first)) == len(a)  # the log shows each of them once
        assert _js(first, "state.run.windows.t0") == pytest.approx(change.json()["applied_t"])
        for width, height in ((1366, 768), (800, 1100), (390, 844)):
            first.set_viewport_size({"width": width, "height": height})
            time.sleep(0.8)
            first.screenshot(path=str(artifacts / f"dashboard-{width}.png"), full_page=True, timeout=120_000)
            # nothing sticks out sideways: the page is as wide as the window
            assert _js(first, "document.documentElement.scrollWidth") <= width + 1, width
        httpx.post(f"{srv.url}/api/runs/{run_id}/stop", timeout=10)
        assert not errors and not errors2, (errors, errors2)
        first.close()
        second.close()


def test_comparison_label_and_delete(browser, tmp_path, small_cfg, artifacts) -> None:
    with _fake_server(tmp_path, small_cfg) as srv:
        ids = []
        for osc in (False, True):
            body = {"duration": 8.0, "reference": {"setpoint": 900.0, "t_E": 4.0}, "oscillation": {"enabled": osc}}
            ids.append(httpx.post(f"{srv.url}/api/runs", json=body, timeout=30).json()["id"])
        for run_id in ids:
            wait = time.monotonic() + 60
            while httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=10).json()["status"] != "finished":
                assert time.monotonic() < wait
                time.sleep(0.1)
        page, errors = open_dashboard(browser, srv.url)
        page.click(".tab[data-view=runs]")
        page.wait_for_selector(f"#history tr[data-id='{ids[1]}']")
        # the list: start time, reference, oscillation, status and errors per run
        row = _text(page, f"#history tr[data-id='{ids[1]}']")
        assert "900 K / 4 s" in row and "on (48 mm" in row and "finished" in row and "%" in row
        for run_id in ids:
            page.check(f"#history tr[data-id='{run_id}'] input.cmp")
        page.wait_for_function("document.getElementById('cmp-mean').data && document.getElementById('cmp-mean')"
                               ".data.length === 4", timeout=30_000)  # two runs x (mean, reference)
        assert _js(page, "document.getElementById('cmp-sup').data.length") == 2
        assert _js(page, "document.getElementById('cmp-tc4').data.length") == 2
        assert _js(page, "document.getElementById('cmp-mean').data[0].x[0]") == pytest.approx(0.1)  # one time axis
        heads = _js(page, "[...document.querySelectorAll('#cmp-table th')].map((th) => th.textContent)")
        # the runs by their automatic labels (issue 27: not hex ids), then the difference column
        labels = [httpx.get(f"{srv.url}/api/runs/{i}", timeout=10).json()["story"]["auto_label"] for i in ids]
        assert labels[0] == "fixed" and labels[1].startswith("osc 48 mm / ")
        assert heads[0] == "metric" and sorted(heads[1:3]) == sorted(labels) and heads[3] == f"{heads[2]} − {heads[1]}"
        # the table's layout only: the stand-in loop's metrics are in kelvin, not relative like the real loop's;
        # the figures and the overlaid series are checked on the real loop in test_browser_truth.py
        assert "Mean error, transient (max)" in _text(page, "#cmp-table") and " K · " in _text(page, "#cmp-table")
        # a label typed in the list names the run in the comparison
        page.click(f"#history tr[data-id='{ids[1]}'] button.edit")
        page.fill("#history input.label-edit", "oscillating, TC4 middle")
        page.press("#history input.label-edit", "Enter")
        _wait_text(page, f"#history tr[data-id='{ids[1]}']", "oscillating, TC4 middle")
        assert httpx.get(f"{srv.url}/api/runs/{ids[1]}", timeout=10).json()["label"] == "oscillating, TC4 middle"
        page.wait_for_function("[...document.querySelectorAll('#cmp-table th')].some((th) => "
                               "th.textContent.startsWith('oscillating, TC4 middle'))", timeout=30_000)
        page.fill("#run-filter", "oscillating")
        page.wait_for_function("document.querySelectorAll('#history tbody tr').length === 1")
        page.fill("#run-filter", "")
        page.screenshot(path=str(artifacts / "dashboard-compare.png"), full_page=True, timeout=120_000)
        # delete the other run (the dialog asks first)
        page.once("dialog", lambda d: d.accept())
        page.click(f"#history tr[data-id='{ids[0]}'] button.del")
        page.wait_for_function(f"!document.querySelector(\"#history tr[data-id='{ids[0]}']\")", timeout=30_000)
        assert httpx.get(f"{srv.url}/api/runs/{ids[0]}", timeout=10).status_code == 404
        assert not (tmp_path / "data" / "runs" / ids[0]).exists()
        assert not errors, errors
        page.close()


def test_double_click_on_start_starts_one_run(browser, tmp_path, small_cfg) -> None:
    class SlowCheck(FakeFactory):  # the server takes a moment to answer, as with the real model
        def check_reference(self, cfg, ref) -> None:
            time.sleep(0.3)
            super().check_reference(cfg, ref)

    with _fake_server(tmp_path, small_cfg, SlowCheck()) as srv:
        page, errors = open_dashboard(browser, srv.url)
        page.fill("input[name=duration]", "600")
        page.fill("input[name=speed]", "1")
        page.dblclick("#start-btn")  # the second click lands on the disabled button
        # the button is back at the reply: a click right after it (a slow double click) is the same request
        page.evaluate("""() => new Promise((resolve) => {
            const btn = document.getElementById('start-btn'), msg = document.getElementById('start-msg');
            const tick = () => {
                if (!btn.disabled && msg.textContent.includes(': reference')) { btn.click(); resolve(); }
                else setTimeout(tick, 5);
            };
            tick();
        })""")
        _wait_text(page, "#start-msg", "already sent")
        runs = httpx.get(f"{srv.url}/api/runs", timeout=10).json()
        assert len(runs) == 1, [r["id"] for r in runs]
        page.fill("input[name=seed]", "7")  # a changed form is a new start
        page.click("#start-btn")
        page.wait_for_function("document.getElementById('start-msg').textContent.includes(': reference') && "
                               "!document.getElementById('start-msg').textContent.includes('already')")
        page.wait_for_function(f"state.runId !== '{runs[0]['id']}'", timeout=30_000)
        assert len(httpx.get(f"{srv.url}/api/runs", timeout=10).json()) == 2
        for r in httpx.get(f"{srv.url}/api/runs", timeout=10).json():
            httpx.post(f"{srv.url}/api/runs/{r['id']}/stop", timeout=10)
        assert not errors, errors
        page.close()
