"""The estimators in the dashboard (issue 11), in a real browser (Debian chromium via playwright) on a real
server (uvicorn on loopback) with the real closed loop on the small test furnace: a run started from the
form with a shadow estimator shows its calibrated parameters, both TC4 errors and the shadow's field
difference, live and again from its history after a reload; a run with the paper's estimator and no shadow
shows none of these cards.  Screenshots: test-artifacts/."""

from __future__ import annotations

import httpx
import numpy as np
import pytest

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from conftest import open_dashboard

pytestmark = pytest.mark.browser

CARDS = ("param-plot", "shadow-tc4-plot", "shadow-delta-plot")
WIDTH, HEIGHT = 1366, 768  # the laptop screen the dashboard is laid out for


@pytest.fixture(scope="module")
def server(tmp_path_factory, small_cfg):
    s = Settings(data_dir=tmp_path_factory.mktemp("browser-estimators"), viser_port=0)
    with ThreadedServer(create_app(s, small_cfg), free_port()) as srv:
        yield srv


def _shown(page) -> dict[str, bool]:
    return page.evaluate(f"Object.fromEntries({list(CARDS)}.map((id) => [id, !document.getElementById("
                         "`card-${id}`).hidden]))")


def _start(page, estimator: str, shadow: str, duration: str = "60", speed: str = "5", osc: bool = False) -> str:
    """Start from the form: 900 K in 25 s (the small furnace needs about 22 s), then hold (a calibrating
    estimator learns only while the reference holds, twin.runs.estimators)."""
    page.check("input[name=refmode][value=transition]")
    page.fill("input[name=setpoint]", "900")
    page.fill("input[name=t_E]", "25")
    page.set_checked("input[name=osc]", osc)
    page.click("#estimator-box summary")
    page.select_option("#start-form [name=estimator]", estimator)
    page.select_option("#start-form [name=shadow]", shadow)
    page.fill("input[name=duration]", duration)
    page.fill("input[name=speed]", speed)
    page.click("#start-btn")
    page.wait_for_function("document.getElementById('start-msg').textContent.includes(': reference')", timeout=120_000)
    return page.evaluate("state.runId")


def _screenshot(page, path) -> None:
    """The window as a user sees it with the shown run's view scrolled down to the estimator cards."""
    page.evaluate("document.querySelector('.view[data-view=live]').scrollTo(0, 1e6)")
    page.wait_for_timeout(800)  # a redraw after the scroll
    page.screenshot(path=str(path), timeout=120_000)
    page.evaluate("document.querySelector('.view[data-view=live]').scrollTo(0, 0)")


def _wait_done(url: str, run_id: str, timeout: float = 300.0) -> dict:
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        run = httpx.get(f"{url}/api/runs/{run_id}", timeout=10).json()
        if run["status"] in ("finished", "stopped", "error"):
            return run
        time.sleep(0.5)
    raise AssertionError(f"run {run_id} did not end within {timeout} s")


def test_a_shadow_run_from_the_form_shows_the_three_estimator_cards(server, browser, artifacts, small_cfg) -> None:
    page, errors = open_dashboard(browser, server.url, WIDTH, HEIGHT)
    # before any run: no estimator card; the form preselects the server's default estimator (GET /api/furnace)
    assert _shown(page) == dict.fromkeys(CARDS, False)
    default = httpx.get(f"{server.url}/api/furnace", timeout=10).json()["defaults"]["estimator"]
    key = lambda c: c["motion"] + ("+calibrate" if c["calibrate"] else "")  # noqa: E731  (the options' values)
    assert page.evaluate("[document.querySelector('#start-form [name=estimator]').value, "
                         "document.querySelector('#start-form [name=shadow]').value]") == [
        key(default), key(default["shadow"]) if default["shadow"] else "none"]
    options = page.evaluate("[...document.querySelector('#start-form [name=estimator]').options].map((o) => o.text)")
    assert options == ["position-aware, calibrating", "position-aware", "paper: averaged, no calibration"]

    # an oscillating specimen, where the two estimators' models differ (the paper's averages over the period)
    run_id = _start(page, "position_aware+calibrate", "averaged", osc=True)  # the paper's estimator as the shadow
    run = httpx.get(f"{server.url}/api/runs/{run_id}", timeout=10).json()
    assert run["scenario"]["estimator"] == {"motion": "position_aware", "calibrate": True,
                                            "shadow": {"motion": "averaged", "calibrate": False}}
    # the three cards appear with data from the live frames
    page.wait_for_function("document.getElementById('param-plot').data && "
                           "document.getElementById('param-plot').data[2].y.length > 80 && "
                           "document.getElementById('shadow-tc4-plot').data && "
                           "document.getElementById('shadow-delta-plot').data", timeout=180_000)
    assert _shown(page) == dict.fromkeys(CARDS, True)
    assert "shadow averaged, no calibration" in page.inner_text("#run-details")
    # parameters: the calibrated ones of the small furnace (lamp efficiency, emissivity), each as a band
    # (value - sigma, value + sigma) and its value line, in % of the model
    names = page.evaluate("document.getElementById('param-plot').data.filter((d) => d.name).map((d) => d.name)")
    assert names == ["lamp efficiency ±1σ", "emissivity ±1σ"]  # twin config calibration.parameters, in order
    # a drawn sample (the traces' y are copies taken at the last redraw, x is the growing time axis): checked
    # against the run's stored series once it has ended
    live = page.evaluate("""(() => {
        const d = document.getElementById('param-plot').data, k = d[2].y.length - 1;
        const e = document.getElementById('shadow-tc4-plot').data;
        return {t: d[2].x[k], lo: d[0].y[k], hi: d[1].y[k], v: d[2].y[k], est: e[0].y[k], sh: e[1].y[k],
                names: e.map((x) => x.name), n: e[1].y.length, nn: e[1].y.filter((v) => v !== null).length};
    })()""")
    # TC4: reading - estimate for the run's estimator and for the shadow, named by their choices
    assert live["names"] == ["estimate: position-aware, calibrating", "shadow: averaged, no calibration"]
    assert live["nn"] == live["n"] > 20  # every sample has the shadow's error
    # the field difference: the grid of the furnace, centred at 0 (zmin = -zmax), the frame's own numbers
    delta = page.evaluate("""(() => {
        const d = document.getElementById('shadow-delta-plot').data[0];
        return {z: d.z, zmin: d.zmin, zmax: d.zmax, zmid: d.zmid, frame: state.series.shadowDelta};
    })()""")
    ny, nx = small_cfg.specimen.ny, small_cfg.specimen.nx
    assert len(delta["z"]) == ny and len(delta["z"][0]) == nx
    flat = [v for row in delta["z"] for v in row]
    assert all(v is not None for v in flat) and max(abs(v) for v in flat) > 0.0  # two estimators differ somewhere
    assert delta["zmid"] == 0 and delta["zmin"] == -delta["zmax"]
    assert delta["zmax"] >= max(abs(v) for v in flat) * 0.999
    _screenshot(page, artifacts / "dashboard-estimators-live.png")

    # after the end, a reload reads the whole history (GET .../series): the same cards, from the first sample on
    ended = _wait_done(server.url, run_id)
    assert ended["status"] == "finished", ended.get("error")
    page.reload()
    page.wait_for_function("document.getElementById('server-state').textContent.startsWith('server ok')",
                           timeout=120_000)
    page.wait_for_function(f"state.runId === '{run_id}' && !state.loading && document.getElementById('param-plot')"
                           ".data && document.getElementById('shadow-delta-plot').data", timeout=60_000)
    assert _shown(page) == dict.fromkeys(CARDS, True)
    stored = httpx.get(f"{server.url}/api/runs/{run_id}/series", timeout=30).json()
    assert len(stored["t"]) < 2000  # not decimated: every sample, as the live charts had them
    k = min(range(len(stored["t"])), key=lambda i: abs(stored["t"][i] - live["t"]))
    value, sigma = stored["parameters"]["lamp_efficiency"][k], stored["parameter_sigma"]["lamp_efficiency"][k]
    assert stored["t"][k] == pytest.approx(live["t"]) and sigma > 0
    assert live["v"] == pytest.approx(100 * value)  # a relative deviation shown in %, with its sigma band
    assert [live["lo"], live["hi"]] == pytest.approx([100 * (value - sigma), 100 * (value + sigma)])
    tc4, tc4_hat, shadow_hat = stored["tc"][k][3], stored["tc_hat"][k][3], stored["shadow_tc_hat"][k][3]
    assert [live["est"], live["sh"]] == pytest.approx([tc4 - tc4_hat, tc4 - shadow_hat], abs=2e-4)  # frames: 4 decimals
    xs = page.evaluate("document.getElementById('param-plot').data[2].x")
    assert xs[0] == pytest.approx(stored["t"][0]) and len(xs) == len(stored["t"])
    assert page.evaluate("document.getElementById('param-plot').data[2].y.slice(-1)[0]") == pytest.approx(
        100 * stored["parameters"]["lamp_efficiency"][-1])
    assert page.evaluate("document.getElementById('shadow-tc4-plot').data[1].y.slice(-1)[0]") == pytest.approx(
        stored["tc"][-1][3] - stored["shadow_tc_hat"][-1][3])
    assert np.asarray(page.evaluate("document.getElementById('shadow-delta-plot').data[0].z")) == pytest.approx(
        np.asarray(stored["shadow_field_delta"]))
    _screenshot(page, artifacts / "dashboard-estimators.png")
    assert page.evaluate("document.documentElement.scrollWidth") <= WIDTH + 1  # nothing sticks out sideways
    # the metrics of both estimators side by side, and the learned parameters at the end
    metrics = httpx.get(f"{server.url}/api/runs/{run_id}", timeout=10).json()["metrics"] or {}
    assert {"shadow", "calibration"} <= set(metrics), f"the run's metrics lack the estimators': {sorted(metrics)}"
    page.wait_for_function("document.getElementById('run-metrics').textContent.includes('shadow %')", timeout=30_000)
    assert "calibrated at the end (vs the model): lamp efficiency" in page.inner_text("#run-metrics")
    page.locator("#run-info").screenshot(path=str(artifacts / "dashboard-estimators-metrics.png"), timeout=120_000)
    assert not errors, errors
    page.close()


def _drawn(page, run_id: str, n: int = 20, timeout: float = 180_000) -> None:
    """Wait until the page shows run_id with more than n samples, drawn after its latest frame."""
    page.wait_for_function(f"state.runId === '{run_id}' && !state.loading && state.series.t.length > {n} && "
                           "!state.dirty", timeout=timeout)


def test_a_run_without_calibration_or_shadow_shows_none_of_them(server, browser, artifacts) -> None:
    # first the page shows a run with both (a short one, started through the API): its cards are there
    body = {"duration": 6.0, "speed": "max", "reference": {"setpoint": 900.0, "t_E": 25.0},
            "estimator": {"motion": "position_aware", "calibrate": True, "shadow": {"motion": "averaged",
                                                                                      "calibrate": False}}}
    r = httpx.post(f"{server.url}/api/runs", json=body, timeout=120)
    assert r.status_code == 201, r.text
    assert _wait_done(server.url, r.json()["id"])["status"] == "finished"
    page, errors = open_dashboard(browser, server.url, WIDTH, HEIGHT)
    _drawn(page, r.json()["id"])
    assert _shown(page) == dict.fromkeys(CARDS, True)
    # the paper's estimator without a shadow, from the form: the cards go with the run they belonged to
    run_id = _start(page, "averaged", "none", duration="20")
    run = httpx.get(f"{server.url}/api/runs/{run_id}", timeout=10).json()
    assert run["scenario"]["estimator"] == {"motion": "averaged", "calibrate": False, "shadow": None}
    _drawn(page, run_id)
    assert _shown(page) == dict.fromkeys(CARDS, False)
    assert page.evaluate("state.lastFrame.calibration === undefined && state.lastFrame.shadow === undefined")
    ended = _wait_done(server.url, run_id)
    assert ended["status"] == "finished", ended.get("error")
    page.reload()
    _drawn(page, run_id, n=150, timeout=120_000)  # the whole history: 20 s at 0.1 s
    assert _shown(page) == dict.fromkeys(CARDS, False)  # nor from its history
    assert "shadow %" not in page.inner_text("#run-metrics")
    assert "calibrated at the end" not in page.inner_text("#run-metrics")
    page.screenshot(path=str(artifacts / "dashboard-estimators-paper.png"), timeout=120_000)
    assert not errors, errors
    page.close()
