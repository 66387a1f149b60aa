"""schemathesis against ``/openapi.json`` of a live server, with its default settings: 100 examples per
operation (hypothesis' default) and its 10 s request timeout.  No request may end in a 5xx or time out.

The server's slow parts are there, without their CPU cost: the loop factory is the conftest's fast
stand-in, made to warm up for its first seconds (``ready()`` false: runs wait as ``queued``, as behind a
radiation model being ray-traced) and to take 8 s per re-plan (a PUT then answers ``pending`` after the
server's default 5 s wait instead of holding the request past the client's timeout).  The cases are
drawn with hypothesis directly (the schemathesis pytest plugin does not load under pytest 9).
"""

from __future__ import annotations

import time

import schemathesis
from hypothesis import HealthCheck, given, settings

from backend.app import create_app
from backend.core.settings import Settings
from backend.core.threaded_server import ThreadedServer, free_port
from backend.runs.loop_factory import WarmUpStatus
from conftest import FakeFactory, FakeStudyRunner

WARM_UP_S = 3.0
REPLAN_S = 8.0


class WarmingFakeFactory(FakeFactory):
    """The stand-in loop, not ready for its first WARM_UP_S seconds."""

    def __init__(self) -> None:
        super().__init__(step_cost_s=0.0, replan_s=REPLAN_S)
        self.started = time.monotonic()

    def ready(self, cfg) -> bool:
        return time.monotonic() - self.started >= WARM_UP_S

    def wait_ready(self, cfg, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not self.ready(cfg) and time.monotonic() < end:
            time.sleep(0.05)
        return self.ready(cfg)

    def warm_up_status(self, cfg) -> WarmUpStatus:
        done = min(13, int(13 * (time.monotonic() - self.started) / WARM_UP_S))
        return WarmUpStatus("ready" if self.ready(cfg) else "computing", "ray tracing", done, 13, self.started)


def test_openapi_no_server_errors_no_timeouts(tmp_path, small_cfg) -> None:
    s = Settings(data_dir=tmp_path / "data", max_duration_s=5.0, max_speed=50.0, max_concurrent_runs=2)
    assert s.change_timeout_s < 10.0  # the server's own wait stays under the client's timeout
    seen: list[tuple[str, int]] = []
    slowest: list[tuple[float, str]] = []
    app = create_app(s, small_cfg, loop_factory=WarmingFakeFactory(), study_runner=FakeStudyRunner())
    with ThreadedServer(app, free_port()) as srv:
        schema = schemathesis.openapi.from_url(f"{srv.url}/openapi.json")
        labels = []
        for result in schema.get_all_operations():
            op = result.ok()
            labels.append(op.label)

            @given(case=op.as_strategy())
            @settings(deadline=None, suppress_health_check=list(HealthCheck), database=None)
            def check(case) -> None:
                t0 = time.monotonic()
                response = case.call()  # schemathesis' default timeout (10 s): raises if exceeded
                slowest.append((time.monotonic() - t0, case.operation.label))
                seen.append((case.operation.label, response.status_code))
                assert response.status_code < 500, (case.operation.label, case.body, response.text[:500])

            check()
    # every endpoint of product.md is in the schema and was exercised
    for label in ("GET /api/health", "POST /api/runs", "GET /api/runs", "GET /api/runs/{run_id}",
                  "POST /api/runs/{run_id}/stop", "PUT /api/runs/{run_id}/reference",
                  "PUT /api/runs/{run_id}/oscillation", "PUT /api/runs/{run_id}/faults",
                  "GET /api/runs/{run_id}/metrics", "GET /api/runs/{run_id}/recording",
                  "GET /api/runs/{run_id}/timeseries", "POST /api/studies", "GET /api/studies",
                  "GET /api/studies/{study_id}"):
        assert label in labels, label
        assert any(lbl == label for lbl, _ in seen), label
    assert max(slowest)[0] < 10.0, max(slowest)
