"""Issue 27 item 10 in a real browser (Debian chromium via playwright) on the real loop: at 800 px the side panels
(new run, faults, learnt furnace) start closed so a chart is above the fold, and one click opens the form; at
1600 px a calibrating run's parameters chart sits in the window, said in words against the furnace's bounds.
Screenshots: test-artifacts/layout-800-closed.png, layout-800.png, layout-1600.png."""

from __future__ import annotations

import httpx
import pytest

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from conftest import open_dashboard, wait_model_ready

pytestmark = pytest.mark.browser

#: where a card's top and bottom are in the window, and whether a side panel is open
BOX = "(sel) => { const r = document.querySelector(sel).getBoundingClientRect(); return [r.top, r.bottom]; }"


@pytest.fixture(scope="module")
def server(tmp_path_factory, small_cfg):
    s = Settings(data_dir=tmp_path_factory.mktemp("layout"), change_timeout_s=120.0)
    with ThreadedServer(create_app(s, small_cfg), free_port()) as srv:
        with httpx.Client(base_url=srv.url, timeout=10) as c:
            wait_model_ready(c)
        yield srv


def _open_panels(page) -> dict[str, bool]:
    return page.evaluate("Object.fromEntries(['new-run', 'controls', 'faults', 'learnt'].map((id) => "
                         "[id, document.querySelector(`#${id} details.panel`).open]))")


def test_at_800_px_the_charts_come_first_and_at_1600_the_parameters_are_in_the_window(server, browser,
                                                                                      artifacts) -> None:
    page, errors = open_dashboard(browser, server.url, 800, 900)
    assert _open_panels(page) == {"new-run": False, "controls": True, "faults": False, "learnt": False}
    assert not page.is_visible("#start-btn") and not page.is_visible("#fault-add")
    # the heat map and the first row of charts begin above the fold
    for card in ("#card-heatmap", "#card-mean"):
        top, _ = page.evaluate(BOX, card)
        assert top < 900, (card, top)
    page.screenshot(path=str(artifacts / "layout-800-closed.png"), timeout=120_000)
    page.click("#new-run summary")
    assert page.is_visible("#start-btn")
    page.fill("input[name=setpoint]", "800")
    page.fill("input[name=t_E]", "20")
    page.fill("input[name=duration]", "40")
    page.fill("input[name=speed]", "max")
    page.click("#start-btn")
    page.wait_for_function("state.run && state.run.status === 'finished' && !state.loading", timeout=240_000)
    page.wait_for_function("!document.getElementById('card-param-plot').hidden", timeout=30_000)
    page.evaluate("window.scrollTo(0, 0)")
    page.screenshot(path=str(artifacts / "layout-800.png"), timeout=120_000)

    # wider: every panel open again, and the 7th chart (calibrated parameters) within a 1600 x 900 window
    page.set_viewport_size({"width": 1600, "height": 900})
    page.wait_for_function("document.querySelector('#faults details.panel').open")
    assert all(_open_panels(page).values())
    page.wait_for_timeout(800)  # the charts' resize
    top, bottom = page.evaluate(BOX, "#card-param-plot")
    assert 0 <= top and bottom <= 900, (top, bottom)
    assert page.evaluate("document.documentElement.scrollWidth") <= 1601

    # the words: every parameter, at its bound exactly when the last estimate is there (0.5 % points)
    furnace = httpx.get(f"{server.url}/api/furnace", timeout=10).json()
    bounds = furnace["calibration_bounds"]
    run_id = page.evaluate("state.runId")
    params = httpx.get(f"{server.url}/api/runs/{run_id}/series", timeout=30).json()["parameters"]
    words = page.inner_text("#param-words")
    assert "Each line: how far the twin's estimate" in words and "dashed: the bounds" in words
    names = {"lamp_efficiency": "lamp efficiency", "emissivity": "emissivity", "convection": "convection"}
    assert params, "a calibrating run reports its parameters"
    for name, values in params.items():
        v = [x for x in values if x is not None][-1]
        lo, hi = bounds[name]
        at = lo if v <= lo + 0.005 else hi if v >= hi - 0.005 else None
        if at is not None:
            sign = "+" if at >= 0 else "−"
            assert f"{names[name]} at its {sign}{abs(100 * at):.1f} % bound" in words, words
        else:
            assert f"{names[name]} {'+' if v >= 0 else '−'}{abs(100 * v):.1f} %" in words, words
    page.screenshot(path=str(artifacts / "layout-1600.png"), timeout=120_000)
    assert not errors, errors
    page.close()
