"""Issue 27 items 5, 6 and 9 in chromium on a real server with the real closed loop (small furnace): a run changed
live reads as what happened (runs table, Show list, report); the form takes a decimal comma and clears a refusal
once it is fixed; a start says queued / running, never "started"; the comparison names runs by their labels,
shades the windows, has a difference column and reads true against estimated.

Screenshots go to test-artifacts/.
"""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from conftest import open_dashboard, wait_model_ready

pytestmark = pytest.mark.browser


#: every 100 ms: the start message line (window.startMsgs, distinct texts in order)
WATCH_START = """
window.startMsgs = [];
setInterval(() => {
  const t = document.getElementById('start-msg').textContent;
  if (t && window.startMsgs[window.startMsgs.length - 1] !== t) window.startMsgs.push(t);
}, 100);
"""


@pytest.fixture(scope="module")
def server(tmp_path_factory, small_cfg):
    s = Settings(data_dir=tmp_path_factory.mktemp("ux"), change_timeout_s=120.0)
    with ThreadedServer(create_app(s, small_cfg), free_port()) as srv:
        with httpx.Client(base_url=srv.url, timeout=10) as c:
            wait_model_ready(c)
        yield srv


def _save(artifacts: Path, name: str, data: bytes | None = None, page=None, selector: str | None = None) -> None:
    path = artifacts / name
    if page is not None:
        (page.locator(selector) if selector else page).screenshot(path=str(path), timeout=120_000)
    else:
        assert data is not None
        path.write_bytes(data)


def _fill_start(page, setpoint: float, t_E: float, duration: float, speed: str, osc: bool) -> None:
    page.check("input[name=refmode][value=transition]")
    page.fill("input[name=setpoint]", str(setpoint))
    page.fill("input[name=t_E]", str(t_E))
    page.fill("input[name=duration]", str(duration))
    page.fill("input[name=speed]", speed)
    page.set_checked("input[name=osc]", osc)


def _start(page) -> str:
    before = page.evaluate("state.runId")
    page.click("#start-btn")
    page.wait_for_function("([b]) => state.runId && state.runId !== b", arg=[before], timeout=60_000)
    return str(page.evaluate("state.runId"))


def _msg(page, id_: str) -> str:
    return str(page.evaluate(f"document.getElementById('{id_}').textContent"))


def test_forms_take_a_decimal_comma_and_a_changed_run_reads_as_what_happened(server, browser, artifacts) -> None:
    page, errors = open_dashboard(browser, server.url, 1500, 950)
    page.evaluate(WATCH_START)
    # the faults form reads numbers the same way: a thousands separator refused in words, a decimal comma taken
    page.select_option("#fault-target", "TC2")
    page.select_option("#fault-kind", "offset")
    page.fill("#fault-value", "2,5")
    page.fill("#fault-at", "1.234,5")
    page.click("#fault-add")
    page.wait_for_function("document.getElementById('fault-msg').classList.contains('err')", timeout=5_000)
    assert "In (s from now)" in _msg(page, "fault-msg") and "not a number" in _msg(page, "fault-msg")
    page.fill("#fault-at", "1,5")
    page.click("#fault-add")
    page.wait_for_function("document.getElementById('fault-pending').textContent.includes('in 1.5 s')", timeout=5_000)
    assert "2.5" in page.inner_text("#fault-pending") and _msg(page, "fault-msg") == ""
    _fill_start(page, 800.0, 20.0, 600.0, "2", osc=False)  # long enough for a loaded machine; stopped below
    # a thousands separator is refused plainly (not read as 1234.5 m nor as 1.2345 m)
    page.fill("input[name=amplitude]", "1.234,5")
    page.click("#start-btn")
    page.wait_for_function("document.getElementById('start-msg').classList.contains('err')", timeout=10_000)
    refused = _msg(page, "start-msg")
    assert "Amplitude" in refused and "1.234,5" in refused and "not a number" in refused, refused
    assert page.evaluate("state.runId") is None
    # fixed with a decimal comma: the refusal goes at once, and 0,03 is 0.03 m (issue 27: "0,048" became 48 m)
    page.fill("input[name=amplitude]", "0,03")
    page.wait_for_function("document.getElementById('start-msg').textContent === ''", timeout=5_000)
    assert "invalid" not in (page.get_attribute("input[name=amplitude]", "class") or "")
    page.fill("input[name=period]", "12")
    run_id = _start(page)
    assert httpx.get(f"{server.url}/api/runs/{run_id}", timeout=10).json()["scenario"]["oscillation"][
        "amplitude"] == pytest.approx(0.03)

    # the start message follows the run: queued / starting / running, never "started"
    page.wait_for_function("state.run && state.run.status === 'running' && !document.getElementById('ref-btn')"
                           ".disabled", timeout=180_000)
    page.wait_for_function("document.getElementById('start-msg').textContent.includes(' running')", timeout=10_000)
    said = page.evaluate("window.startMsgs")
    assert not any("started" in m for m in said), said
    mine = [m for m in said if m.startswith(f"run {run_id} ")]
    assert mine[0].split(":")[0] in (f"run {run_id} queued", f"run {run_id} starting"), said
    assert mine[-1].startswith(f"run {run_id} running: reference 800 K in 20 s"), said

    # live: a new reference, then oscillation on with a decimal comma in the live amplitude
    page.check("input[name=live-refmode][value=transition]")
    page.fill("#new-setpoint", "750")
    page.fill("#new-tE", "10")
    page.click("#ref-btn")
    page.wait_for_function("document.getElementById('ctl-msg').textContent.includes('applied at t =')",
                           timeout=120_000)
    page.fill("#live-amplitude", "0,5")  # 0.5 m: over the furnace's eta_max, refused by the page
    page.click("#osc-btn")
    try:
        page.wait_for_function("document.getElementById('ctl-msg').classList.contains('err')", timeout=10_000)
    finally:
        _save(artifacts, "ux-live-refused.png", page=page)
    assert "Amplitude" in _msg(page, "ctl-msg") and "at most" in _msg(page, "ctl-msg"), _msg(page, "ctl-msg")
    page.fill("#live-amplitude", "0,03")
    page.wait_for_function("document.getElementById('ctl-msg').textContent === ''", timeout=5_000)
    page.fill("#live-period", "12")
    page.click("#osc-btn")
    page.wait_for_function("/oscillation on: applied( at t =)?/.test(document.getElementById('ctl-msg').textContent)",
                           timeout=120_000)
    page.click("#stop-btn")
    page.wait_for_function("state.run && state.run.status === 'stopped' && !state.loading", timeout=300_000)
    page.wait_for_timeout(2500)
    assert "pending" not in _msg(page, "ctl-msg") and "re-planning" not in _msg(page, "ctl-msg"), _msg(page, "ctl-msg")

    run = httpx.get(f"{server.url}/api/runs/{run_id}", timeout=10).json()
    applied = {c["kind"]: c["applied_t"] for c in run["changes"] if c["status"] == "applied"}
    story = run["story"]
    # from the changes the server recorded (an independent record of what the loop applied)
    assert story["reference"] == f"750 K / 10 s (changed at {applied['reference']:.1f} s)", story
    assert story["oscillation"] == f"on from {applied['oscillation']:.1f} s (30 mm / 12 s)", story
    assert story["auto_label"] == f"osc 30 mm / 12 s from {applied['oscillation']:.1f} s", story
    assert run["label"] is None

    # the runs table, the Show list and the run's details say the same
    page.click("button.tab[data-view=runs]")
    page.wait_for_selector(f"#history tr[data-id='{run_id}']", timeout=30_000)
    row = page.inner_text(f"#history tr[data-id='{run_id}']")
    assert story["reference"] in row and story["oscillation"] in row and story["auto_label"] in row, row
    assert "800 K / 20 s" not in row, row
    option = page.inner_text(f"#run-pick option[value='{run_id}']")
    assert story["text"] in option and story["auto_label"] in option, option
    _save(artifacts, "ux-runs-table.png", page=page, selector="#history")
    # the automatic label is editable as before: a name typed replaces it
    page.click(f"#history tr[data-id='{run_id}'] button.edit")
    page.fill("input.label-edit", "osc after the change")
    page.press("input.label-edit", "Enter")
    page.wait_for_function(f"document.querySelector(\"#history tr[data-id='{run_id}'] button.name\")"
                           "?.textContent === 'osc after the change'", timeout=15_000)  # the row is redrawn

    # the report's header and file name
    rep = httpx.get(f"{server.url}/api/runs/{run_id}/report.png", timeout=180)
    assert rep.status_code == 200
    assert f'filename="osc-after-the-change-{run_id}.png"' in rep.headers["content-disposition"]
    _save(artifacts, "ux-report.png", data=rep.content)
    assert not errors, errors
    page.close()


def test_the_comparison_answers_did_oscillation_help(server, browser, artifacts) -> None:
    """Two runs of the same reference, fixed and oscillating, compared: labels in legends and columns, the
    windows shaded, a difference column, and the true-vs-estimated reading."""
    page, errors = open_dashboard(browser, server.url, 1500, 950)
    ids = []
    for osc in (False, True):
        _fill_start(page, 800.0, 20.0, 45.0, "max", osc=osc)
        page.fill("input[name=amplitude]", "0.03")
        page.fill("input[name=period]", "12")
        ids.append(_start(page))
        page.wait_for_function("state.run && ['finished', 'error'].includes(state.run.status) && !state.loading",
                               timeout=300_000)
        assert page.evaluate("state.run.status") == "finished"
    page.click("button.tab[data-view=runs]")
    for run_id in ids:
        page.wait_for_selector(f"#history tr[data-id='{run_id}'] input.cmp", timeout=30_000)
        page.check(f"#history tr[data-id='{run_id}'] input.cmp")
    page.wait_for_function("document.getElementById('cmp-verdict').textContent.length > 0", timeout=60_000)
    page.wait_for_timeout(1000)
    legend = page.evaluate("document.getElementById('cmp-mean').data.filter((d) => d.showlegend !== false)"
                           ".map((d) => d.name)")
    assert legend == ["fixed", "osc 30 mm / 12 s"], legend
    heads = page.evaluate("[...document.querySelectorAll('#cmp-table th')].map((th) => th.textContent)")
    assert heads == ["metric", "fixed", "osc 30 mm / 12 s", "osc 30 mm / 12 s − fixed"], heads
    shapes = page.evaluate("(document.getElementById('cmp-sup').layout.shapes || []).map((s) => [s.x0, s.x1])")
    windows = httpx.get(f"{server.url}/api/runs/{ids[0]}", timeout=10).json()["windows"]
    assert shapes and shapes[0] == pytest.approx(windows["transient"]), (shapes, windows)

    # the difference column and the reading from the metrics the server stored
    m = [httpx.get(f"{server.url}/api/runs/{i}", timeout=10).json()["metrics"] for i in ids]
    row = page.evaluate("[...document.querySelectorAll('#cmp-table tr')].find((tr) => tr.cells[0].textContent"
                        ".startsWith('True T_sup, steady')).cells[3].textContent")
    d = 100 * (m[1]["true_inhomogeneity_steady"] - m[0]["true_inhomogeneity_steady"])
    assert f"{abs(d):.2f} pts" in row and (d >= 0 or row.split("K · ")[1].startswith("\u2212")), (row, d)
    reading = page.inner_text("#cmp-verdict")
    assert "true field" in reading and "the true field judges" in reading, reading
    assert f"{100 * m[1]['true_inhomogeneity_steady']:.2f} %" in reading, reading
    assert f"{100 * m[1]['inhomogeneity_steady']:.2f} %" in reading, reading
    assert ("lower (better)" in reading) == (d < -0.01), reading  # the page says "the same" within 1e-4
    _save(artifacts, "ux-compare.png", page=page, selector="#compare")
    assert not errors, errors
    page.close()
