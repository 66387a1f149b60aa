"""The 3D view's run choice (viser's own server, no browser): it follows the newest running run, or
the run picked in its dropdown; a finished run shows its last estimated field from timeseries.npz,
and the live controls act only on a picked run that still runs."""

from __future__ import annotations

import numpy as np
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import free_port
from backend.viser import AUTO, colour_range, stored_snapshot, turbo_rgb, vertex_values
from conftest import fake_factory, wait_status


def _live_controls(view) -> list[bool]:
    g = view.gui
    return [not h.disabled for h in (g.new_setpoint, g.new_t_E, g.change_reference, g.toggle_oscillation, g.stop)]


def test_pick_a_finished_run_and_back(tmp_path, small_cfg) -> None:
    s = Settings(data_dir=tmp_path / "data", viser_port=free_port(), change_timeout_s=120.0)
    app = create_app(s, small_cfg, loop_factory=fake_factory(), viser=True)
    with TestClient(app, base_url="http://127.0.0.1") as c:
        view = app.state.viser
        assert view.host == "127.0.0.1" and app.state.viser_url.startswith("http://127.0.0.1:")
        view._stop.set()  # drive the updates from the test instead of the view's thread
        view._thread.join(timeout=5)
        done = c.post("/api/runs", json={"duration": 3.0, "reference": {"points": [[1.0, 700.0]]}}).json()["id"]
        wait_status(c, done, {"finished"})
        live = c.post("/api/runs", json={"duration": 600.0, "speed": 2.0}).json()["id"]
        wait_status(c, live, {"running"})
        c.get(f"/api/runs/{live}")  # let a few samples through
        view.refresh_runs(force=True)
        options = list(view.gui.run.options)
        assert options[0] == AUTO and len(options) == 3
        assert any(o.startswith(done) and "1 points to 700 K" in o for o in options)
        assert any(o.startswith(live) for o in options)

        view.update()  # nothing picked: the newest running run
        assert f"run `{live}`" in view.gui.status.content and "running" in view.gui.status.content
        assert view._followed() == live and all(_live_controls(view))

        view.pick(done)
        assert view.gui.run.value.startswith(done) and view.follow == done
        view.update()
        assert f"run `{done}`" in view.gui.status.content and "finished" in view.gui.status.content
        last = stored_snapshot(tmp_path / "data" / "runs" / done / "timeseries.npz",
                               (small_cfg.specimen.ny, small_cfg.specimen.nx))
        assert last is not None and last.has_field and last.t == 3.0
        assert "t = 3.0 s (last sample)" in view.gui.status.content
        expected = turbo_rgb(vertex_values(last.field_hat), *colour_range(last.field_hat))
        np.testing.assert_array_equal(view.scene.plate_rgb, expected)  # the finished run's last field is drawn
        # the live controls never reach the other (running) run while a finished one is shown: disabled
        assert view._followed() is None and done in view._not_running()
        assert not any(_live_controls(view))

        view.pick(None)  # back to following the running run
        assert view.gui.run.value == AUTO
        view.update()
        assert f"run `{live}`" in view.gui.status.content and view._followed() == live
        c.post(f"/api/runs/{live}/stop")
        wait_status(c, live, {"stopped"})
        view.update()  # the followed run ended: its last sample, from its file
        assert f"run `{live}`" in view.gui.status.content and "stopped" in view.gui.status.content
        assert not any(_live_controls(view))  # no running run left to act on
