"""schemathesis against ``/openapi.json`` of a live server: no request may end in a 5xx.

Bounded: a few examples per operation (positive and negative data).  The server runs the
conftest's fast stand-in loop (runs here are about input handling, not physics), with small
limits so generated runs end quickly.  The cases are drawn with hypothesis directly (the
schemathesis pytest plugin does not load under pytest 9).
"""

from __future__ import annotations

import schemathesis
from hypothesis import HealthCheck, given, settings

from backend.app import create_app
from backend.settings import Settings
from backend.threaded_server import ThreadedServer, free_port
from conftest import FakeStudyRunner, fake_factory

EXAMPLES = 6


def test_openapi_no_server_errors(tmp_path, small_cfg) -> None:
    s = Settings(data_dir=tmp_path / "data", max_duration_s=5.0, max_speed=50.0, max_concurrent_runs=2,
                 change_timeout_s=2.0)
    seen: list[tuple[str, int]] = []
    app = create_app(s, small_cfg, loop_factory=fake_factory(), study_runner=FakeStudyRunner())
    with ThreadedServer(app, free_port()) as srv:
        schema = schemathesis.openapi.from_url(f"{srv.url}/openapi.json")
        labels = []
        for result in schema.get_all_operations():
            op = result.ok()
            labels.append(op.label)

            @given(case=op.as_strategy())
            @settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck),
                      database=None)
            def check(case) -> None:
                response = case.call(timeout=30)
                seen.append((case.operation.label, response.status_code))
                assert response.status_code < 500, (case.operation.label, case.body, response.text[:500])

            check()
    # every endpoint of product.md is in the schema and was exercised
    for label in ("GET /api/health", "POST /api/runs", "GET /api/runs", "GET /api/runs/{run_id}",
                  "POST /api/runs/{run_id}/stop", "PUT /api/runs/{run_id}/reference",
                  "PUT /api/runs/{run_id}/oscillation", "GET /api/runs/{run_id}/metrics",
                  "GET /api/runs/{run_id}/recording", "GET /api/runs/{run_id}/timeseries",
                  "POST /api/studies", "GET /api/studies", "GET /api/studies/{study_id}"):
        assert label in labels, label
        assert any(lbl == label for lbl, _ in seen), label
