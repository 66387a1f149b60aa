"""What a user reads on the dashboard, checked against the run's own files, on the real closed loop.

A real browser (Debian chromium via playwright) on a real server with the real loop on the small furnace:
two short runs (12 s simulated, at full speed), one fixed and one oscillating.  The run card's metrics table
shows each metric as ``100 x`` the value in the run's ``metrics.json`` (in %, two decimals) and as that value
times the setpoint of its windows (in K, one decimal); the comparison overlays exactly the runs' stored
series (``timeseries.npz``: fillet mean, reference, TC4 error) and its table repeats the same figures.  A
unit error in the page's metric display (a percent not multiplied by 100, K with the wrong scale) fails here.
"""

from __future__ import annotations

import io
import json
import re
import time

import httpx
import numpy as np
import pytest

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port

pytestmark = pytest.mark.browser

# short and feasible on the small furnace (a 900 K transition needs t_E >= 22 s there): 120 samples each
RUNS = ({"duration": 12.0, "reference": {"setpoint": 520.0, "t_E": 8.0}},
        {"duration": 12.0, "reference": {"setpoint": 500.0, "t_E": 8.0}, "oscillation": {"enabled": True}})
NUMBER = re.compile(r"[-−]?\d+(?:\.\d+)?")


@pytest.fixture(scope="module")
def finished_runs(tmp_path_factory, small_cfg):
    """The server (real loop) and the two runs, finished: [(id, metrics.json, timeseries arrays)]."""
    data = tmp_path_factory.mktemp("truth")
    with ThreadedServer(create_app(Settings(data_dir=data), small_cfg), free_port()) as srv:
        ids = [httpx.post(f"{srv.url}/api/runs", json=body, timeout=120).json()["id"] for body in RUNS]
        runs = []
        for run_id in ids:
            end = time.monotonic() + 300
            while (status := httpx.get(f"{srv.url}/api/runs/{run_id}", timeout=30).json()["status"]) != "finished":
                assert status in ("queued", "starting", "running") and time.monotonic() < end, status
                time.sleep(0.2)
            saved = json.loads((data / "runs" / run_id / "metrics.json").read_text())
            npz = httpx.get(f"{srv.url}/api/runs/{run_id}/timeseries", timeout=60).content
            with np.load(io.BytesIO(npz)) as z:
                arrays = {k: z[k] for k in ("t", "T_mean_hat", "T_ref", "tc", "tc_hat")}
            runs.append((run_id, saved, arrays))
        yield srv, runs


def _open(browser, url: str):
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url, timeout=120_000)
    page.wait_for_function("document.getElementById('server-state').textContent.startsWith('server ok')",
                           timeout=120_000)
    return page, errors


def _numbers(text: str) -> list[float]:
    return [float(x.replace("−", "-")) for x in NUMBER.findall(text)]


def _metric_rows(page, selector: str) -> dict[str, list[str]]:
    """The metric name (its glossary words) -> the row's other cells' text."""
    return page.evaluate(f"""Object.fromEntries([...document.querySelectorAll('{selector} tbody tr')].map((tr) => {{
        const cells = [...tr.querySelectorAll('td')].map((td) => td.textContent.trim());
        return [cells[0].replace(/\\s*\\?\\s*$/, '').trim(), cells.slice(1)];
    }}))""")


def _names(srv) -> dict[str, str]:
    """Metric key -> the words the dashboard's K / % table shows for it (GET /api/glossary: the metrics relative
    to the setpoint; coverage, NEES, NIS, shares and counts have other units and a note of their own)."""
    from twin.runs.metrics import RELATIVE

    glossary = httpx.get(f"{srv.url}/api/glossary", timeout=30).json()["metrics"]
    return {k: v["name"] for k, v in glossary.items() if v["unit"] == RELATIVE}


def _row_for(rows: dict[str, list[str]], name: str) -> list[str]:
    found = [cells for shown, cells in rows.items() if shown == name]
    assert len(found) == 1, (name, list(rows))
    return found[0]


def test_the_run_card_shows_100_times_metrics_json(finished_runs, browser, artifacts) -> None:
    srv, runs = finished_runs
    names = _names(srv)
    page, errors = _open(browser, srv.url)
    for run_id, saved, _ in runs:
        page.click(".tab[data-view=runs]")
        page.wait_for_selector(f"#history tr[data-id='{run_id}'] button.name")
        page.click(f"#history tr[data-id='{run_id}'] button.name")
        page.wait_for_function(f"state.run && state.run.id === '{run_id}' && state.run.metrics && "
                               "document.querySelectorAll('#run-metrics tbody tr').length > 5", timeout=60_000)
        setpoint = page.evaluate("state.run.windows.setpoint")
        assert setpoint == saved_setpoint(run_id, runs)
        rows = _metric_rows(page, "#run-metrics")
        checked = 0
        for key, name in names.items():
            if key not in saved:  # a metric this run has not (a fixed run: no oscillation amplitude)
                continue
            value = saved[key]
            kelvin, percent = _row_for(rows, name)[:2]
            if value is None:  # NaN in the run (an empty window): null in metrics.json, a dash on the page
                assert (kelvin, percent) == ("–", "–"), key
                continue
            # the table rounds: % to 2 decimals, K to 1
            assert percent.endswith(" %") and _numbers(percent)[0] == pytest.approx(100 * value, abs=0.0051), \
                (key, percent, value)
            assert kelvin.endswith(" K") and _numbers(kelvin)[0] == pytest.approx(value * setpoint, abs=0.051), \
                (key, kelvin, value)
            checked += 1
        assert checked >= 10, checked  # every table metric of product.md with a value
        # the calibration's note (the uncertainty's note follows it)
        cal = next(n for n in page.locator("#run-metrics .note").all_inner_texts() if n.startswith("calibrated"))
        for name, p in saved.get("calibration", {}).items():  # the learned parameters, in % of the model's
            words = name.replace("_", " ")
            shown = cal.split(words, 1)[1]
            value, sigma = _numbers(shown)[:2]
            assert value == pytest.approx(100 * p["value"], abs=0.051) and sigma == pytest.approx(
                100 * p["sigma"], abs=0.051), (name, shown, p)
    page.screenshot(path=str(artifacts / "dashboard-metrics-truth.png"), full_page=True, timeout=120_000)
    assert not errors, errors
    page.close()


def saved_setpoint(run_id: str, runs) -> float:
    """The setpoint of a run's windows: its scenario's (no live change in these runs)."""
    index = [r[0] for r in runs].index(run_id)
    return RUNS[index]["reference"]["setpoint"]


def test_the_comparison_overlays_the_runs_series_and_repeats_their_metrics(finished_runs, browser,
                                                                            artifacts) -> None:
    srv, runs = finished_runs
    names = _names(srv)
    page, errors = _open(browser, srv.url)
    page.click(".tab[data-view=runs]")
    for run_id, _, _ in runs:
        page.wait_for_selector(f"#history tr[data-id='{run_id}'] input.cmp")
        page.check(f"#history tr[data-id='{run_id}'] input.cmp")
    page.wait_for_function("document.getElementById('cmp-mean').data && "
                           "document.getElementById('cmp-mean').data.length === 4", timeout=60_000)
    mean = page.evaluate("document.getElementById('cmp-mean').data.map((d) => ({name: d.name, x: d.x, y: d.y}))")
    tc4 = page.evaluate("document.getElementById('cmp-tc4').data.map((d) => ({name: d.name, x: d.x, y: d.y}))")
    # the runs by their automatic labels (issue 27: not hex ids), then the difference column
    label = {r[0]: httpx.get(f"{srv.url}/api/runs/{r[0]}", timeout=10).json()["story"]["auto_label"] for r in runs}
    heads = page.evaluate("[...document.querySelectorAll('#cmp-table th')].map((th) => th.textContent)")[1:]
    assert sorted(heads[:len(runs)]) == sorted(label.values()) and heads[len(runs):] == [f"{heads[1]} − {heads[0]}"]
    heads = heads[:len(runs)]
    rows = _metric_rows(page, "#cmp-table")
    for run_id, saved, z in runs:
        i = heads.index(label[run_id])  # the traces come in the table's order, two (mean, reference) per run
        est, ref = mean[2 * i], mean[2 * i + 1]
        assert est["name"] == label[run_id] and ref["name"] == f"{label[run_id]} reference"
        # the very samples of the run's timeseries.npz (120 of them: below the page's 1500-point limit)
        np.testing.assert_array_equal(est["x"], z["t"])
        np.testing.assert_array_equal(est["y"], z["T_mean_hat"])
        np.testing.assert_array_equal(ref["y"], z["T_ref"])
        np.testing.assert_allclose(tc4[i]["y"], z["tc"][:, 3] - z["tc_hat"][:, 3], rtol=0, atol=1e-9)
        setpoint = saved_setpoint(run_id, runs)
        for key, name in names.items():
            value = saved.get(key)
            if value is None:
                continue
            cell = _row_for(rows, name)[i]  # "12.3 K · 1.37 %"
            k, p = _numbers(cell)[:2]
            assert p == pytest.approx(100 * value, abs=0.0051) and k == pytest.approx(value * setpoint, abs=0.051), \
                (run_id, key, cell, value)
    page.screenshot(path=str(artifacts / "dashboard-compare-truth.png"), full_page=True, timeout=120_000)
    assert not errors, errors
    page.close()
