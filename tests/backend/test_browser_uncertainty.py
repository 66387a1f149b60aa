"""The dashboard shows the estimate's uncertainty (issue 25): the σ toggle puts field_sigma on the heat map (its own
colour scale and title), and the fillet-mean chart carries the ±2σ band, for a finished run read back from its
stored series.  Screenshots: test-artifacts/dashboard-sigma.png."""

from __future__ import annotations

import httpx
import numpy as np
import pytest

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from conftest import wait_status

pytestmark = pytest.mark.browser


def test_sigma_toggle_and_band(tmp_path, small_cfg, browser, artifacts) -> None:
    s = Settings(data_dir=tmp_path, viser_port=0)
    with ThreadedServer(create_app(s, small_cfg, viser=False), free_port()) as srv:
        with httpx.Client(base_url=srv.url, timeout=60) as c:
            run_id = c.post("/api/runs", json={"duration": 20.0, "reference": {"setpoint": 700.0, "t_E": 10.0},
                                               "seed": 41}).json()["id"]
            wait_status(c, run_id, {"finished"}, timeout=300)
            stored = c.get(f"/api/runs/{run_id}/series").json()
            stored_metrics = c.get(f"/api/runs/{run_id}/metrics").json()
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(srv.url, timeout=120_000)
        page.wait_for_function("window.state && state.series && state.series.fieldSigma", timeout=120_000)
        title = "document.getElementById('heatmap').data[0].colorbar.title.text"
        page.wait_for_function(f"{title} === 'T (K)'", timeout=60_000)
        page.check("#show-sigma")
        page.wait_for_function(f"{title} === 'σ (K)'", timeout=60_000)
        z = np.asarray(page.evaluate("document.getElementById('heatmap').data[0].z"), float)
        np.testing.assert_allclose(z, np.asarray(stored["field_sigma"]), rtol=1e-6)
        band = page.evaluate("document.getElementById('mean-plot').data.filter((d) => d.fill === 'tonexty')"
                             ".map((d) => d.name)")
        assert band == ["fillet mean ± 2σ"]
        assert "2σ" in page.inner_text("#heat-sub")
        note = page.inner_text("#uncertainty-note")  # the run's uncertainty metrics beside its errors
        assert f"steady {100 * stored_metrics['coverage_2sigma_steady']:.1f} %" in note, note
        page.screenshot(path=str(artifacts / "dashboard-sigma.png"), timeout=120_000)
        page.uncheck("#show-sigma")
        page.wait_for_function(f"{title} === 'T (K)'", timeout=60_000)
        assert not errors, errors
