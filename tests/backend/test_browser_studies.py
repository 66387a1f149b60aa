"""The Studies view in a real browser (Debian chromium via playwright) on a real server whose studies run
on a 2-worker Dask LocalCluster: a study typed as JSON runs to the end and shows its progress, best case
per metric, figures and downloads; invalid JSON and a study the server refuses (422) say why on the
message line.  Screenshot: test-artifacts/studies-view.png."""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest
from test_browser import _wait_text

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from conftest import open_dashboard

pytestmark = pytest.mark.browser

TOKEN = "studies-browser-token-0123"
STUDY = {"name": "browser study", "base": {"duration": 12.0, "reference": {"setpoint": 900.0, "t_E": 6.0}},
         "grid": {"tc_noise": [0.5, 1.0], "seed": [1, 2]}}


@pytest.fixture(scope="module")
def server(tmp_path_factory, small_cfg, radiation_cache):
    s = Settings(data_dir=tmp_path_factory.mktemp("studies"), viser_port=0, study_workers=2)
    with ThreadedServer(create_app(s, small_cfg), free_port()) as srv:
        yield srv


def _fill(page, text: str) -> None:
    """The JSON is the advanced box (issue 27 item 8): opened to edit."""
    if not page.evaluate("document.getElementById('study-advanced').open"):
        page.click("#study-advanced summary")
    page.fill("#study-text", text)


def _reading(cases: list[dict], metric: str) -> tuple[bool, float | None]:
    """From the study's own case rows, independently of twin.studies.report: whether the best tc_noise point
    (median over its seeds) beats the next by more than the seed spread (median over the points of max - min)."""
    points: dict[float, list[float]] = {}
    for c in cases:
        points.setdefault(c["params"]["tc_noise"], []).append(c["metrics"][metric])
    medians = sorted(float(np.median(v)) for v in points.values())
    spread = float(np.median([max(v) - min(v) for v in points.values()]))
    return medians[1] - medians[0] > spread, spread


def test_a_study_from_the_studies_view(browser, server, artifacts) -> None:
    page, errors = open_dashboard(browser, server.url)
    page.click("#view-studies")
    assert page.is_hidden("main") and page.is_visible("#studies-view")
    # the example comes with the furnace's default amplitude; the JSON box is closed, the study reads in words
    assert not page.is_visible("#study-text")
    example = json.loads(page.input_value("#study-text"))
    assert example["grid"]["oscillation.amplitude"][-1] == pytest.approx(0.048)
    _wait_text(page, "#study-read", "oscillation.period")
    # before Start: the cases (6 periods x amplitudes, 2 seeds each) and, with no study finished here, no estimate
    _wait_text(page, "#study-plan", "12 cases (6 design points x 2 seeds or samples) on 2 workers; no time estimate")

    _fill(page, "{not json")
    page.click("#study-form button[type=submit]")
    _wait_text(page, "#study-msg", "not valid JSON")
    _fill(page, json.dumps({"grid": {"oscillation.perod": [6.0]}}))
    page.click("#study-form button[type=submit]")
    _wait_text(page, "#study-msg", "oscillation.perod")  # the server's refusal in its words (no status code)
    assert "invalid study" in page.inner_text("#study-msg")
    assert httpx.get(f"{server.url}/api/studies").json() == []

    _fill(page, json.dumps(STUDY))
    _wait_text(page, "#study-plan", "4 cases (2 design points x 2 seeds or samples)")
    page.click("#study-form button[type=submit]")
    _wait_text(page, "#study-msg", "4 cases")
    _wait_text(page, "#study-list", "browser study")
    _wait_text(page, "#study-detail", "finished", timeout=240_000)
    page.wait_for_function("document.querySelectorAll('#study-detail .figures img').length >= 1")
    page.wait_for_function("[...document.querySelectorAll('#study-detail .figures img')].every(i => i.complete"
                           " && i.naturalWidth > 0)")
    detail = page.inner_text("#study-detail")
    assert "4 / 4" in detail and "Best case per metric" in detail
    # metrics by their glossary names, not code keys (issue 27 item 8)
    assert "T_sup, steady (mean)" in detail and "inhomogeneity_steady" not in detail, detail
    links = page.eval_on_selector_all("#study-detail .downloads a", "as => as.map(a => a.textContent)")
    assert set(links) == {"results.parquet", "results.csv", "study.md", "summary.json"}
    csv = httpx.get(server.url + page.get_attribute("#study-detail .downloads a[href$='results.csv']", "href"))
    assert csv.status_code == 200 and len(csv.text.strip().splitlines()) == 5
    assert page.is_disabled("#study-stop") and page.is_disabled("#study-resume")
    # the best case only beyond the seed spread, checked against the cases' own numbers
    body = httpx.get(f"{server.url}/api/studies/{page.evaluate('window.studies.id')}").json()
    row = page.inner_text("#study-detail tr:has(span[title='inhomogeneity_steady'])")
    decided, spread = _reading(body["cases"], "inhomogeneity_steady")
    assert f"{100 * spread:.2f} %" in row, row
    assert (row.split("\t")[-1].startswith("best") if decided else "no case is better than the seed spread" in row), row
    # a study has finished on this server now: the next plan gives an estimated time
    _fill(page, json.dumps(STUDY))
    _wait_text(page, "#study-plan", "(an estimate)")
    page.screenshot(path=str(artifacts / "studies-view.png"), full_page=True)
    assert errors == []


def test_with_a_token_figures_and_downloads_carry_it(browser, tmp_path, small_cfg) -> None:
    """A server with an API token: a study started from the view after entering the token; its figure is
    fetched with the token header (a blob URL) and shows."""
    from conftest import FakeStudyRunner

    s = Settings(data_dir=tmp_path / "data", viser_port=0, api_token=TOKEN)
    with ThreadedServer(create_app(s, small_cfg, study_runner=FakeStudyRunner()), free_port()) as srv:
        page, errors = open_dashboard(browser, srv.url)
        page.wait_for_selector("#token-box", state="visible")
        page.fill("#token", TOKEN)
        page.dispatch_event("#token", "change")
        page.click("#view-studies")
        _fill(page, json.dumps({"name": "with token", "grid": {"tc_noise": [0.5, 1.0]}}))
        page.click("#study-form button[type=submit]")
        _wait_text(page, "#study-detail", "finished", timeout=30_000)
        page.wait_for_function("(() => { const i = document.querySelector('#study-detail .figures img');"
                               " return i && i.src.startsWith('blob:') && i.complete && i.naturalWidth === 1; })()")
        assert errors == []


def test_tc_placement_in_the_studies_view(browser, server, artifacts) -> None:
    # issue 25: place-tcs in the Studies view, on the real ranking (small furnace, the twin's plan and Gramians):
    # the table a user reads is the API's ranking, the map is drawn with both sets of TCs, errors none
    page, errors = open_dashboard(browser, server.url)
    page.click("#view-studies")
    page.click("#place-rank")
    page.wait_for_selector("#place-table tbody tr", timeout=120_000)
    body = httpx.get(f"{server.url}/api/placement", params={"count": 3}, timeout=10).json()
    assert body["state"] == "done" and len(body["positions"]) == 3
    rows = page.evaluate("[...document.querySelectorAll('#place-table tbody tr')].map((r) => "
                         "[...r.cells].map((c) => c.textContent.trim()))")
    want = [[f"#{p['rank']}", f"{p['x']:.4f}", f"{p['y']:.4f}", f"{p['x_rel']:.3f}", f"{p['y_rel']:.3f}",
             f"{p['score']:.1f}"] for p in body["positions"]]
    assert rows == want
    assert f"{body['paper']['score']:.1f} nats" in page.text_content("#place-paper")
    # the map: one heat map over the candidates and the two marker sets (3 recommended, 3 paper)
    traces = page.evaluate("document.getElementById('place-map').data.map((t) => [t.type, (t.x || []).length])")
    assert traces == [["heatmap", len(body["map"]["score"])], ["scatter", 3], ["scatter", 3]]
    assert "ranked in" in page.text_content("#place-msg")
    page.screenshot(path=str(artifacts / "studies-placement.png"), full_page=True)
    assert not errors, errors
