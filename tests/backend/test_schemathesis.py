"""schemathesis against ``/openapi.json`` of a live server: no request may end in a 5xx or time out, and
every operation is reached with a resource that exists (not only with made-up ids that answer 404).

Two parts.  Each operation on its own, ``EXAMPLES`` cases drawn from its schema (limited to keep the suite
fast; the schemathesis CLI, ``st run URL/openapi.json``, runs the full default set), within schemathesis' 10 s
request timeout.  Then the stateful part: schemathesis follows the OpenAPI links (``backend/api/links.py``)
from ``POST /api/runs`` and ``POST /api/studies`` to every operation on the run or study they made.

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
LINKED_EXAMPLES = 10  # cases per operation reached through a link
EXAMPLES = 30  # per operation (hypothesis' default is 100: about 3x the time, no 5xx found beyond 30 here)


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
            @settings(deadline=None, suppress_health_check=list(HealthCheck), database=None, max_examples=EXAMPLES)
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




def _linked(spec: dict, post_path: str) -> dict[str, tuple[str, str, dict[str, str]]]:
    """The links of a POST's 201 response: name -> (target path, method, parameters)."""
    links = spec["paths"][post_path]["post"]["responses"]["201"].get("links", {})
    out = {}
    for name, link in links.items():
        ref = link["operationRef"].removeprefix("#/paths/")
        path, method = ref.rsplit("/", 1)
        out[name] = (path.replace("~1", "/").replace("~0", "~"), method, link["parameters"])
    return out


def _create(op) -> dict:
    """The body of the first 201 to a case schemathesis draws for the POST ``op`` (at most 200 cases)."""
    created: list[dict] = []

    @given(case=op.as_strategy())
    @settings(deadline=None, suppress_health_check=list(HealthCheck), database=None, max_examples=200)
    def create(case) -> None:
        if not created:
            response = case.call()
            assert response.status_code < 500, (op.label, case.body, response.text[:300])
            if response.status_code == 201:
                created.append(response.json())

    create()
    assert created, f"schemathesis drew no body that {op.label} accepts in 200 cases"
    return created[0]


def _follow(op, values: dict[str, str], seen: dict[str, set[int]]) -> None:
    """``LINKED_EXAMPLES`` drawn cases of ``op`` with the link's path parameters ``values``; the status codes
    go into ``seen`` (0 for a 404 about a missing run or study)."""

    @given(case=op.as_strategy())
    @settings(deadline=None, suppress_health_check=list(HealthCheck), database=None, max_examples=LINKED_EXAMPLES)
    def follow(case) -> None:
        case.path_parameters = {**(case.path_parameters or {}), **values}
        response = case.call()
        assert response.status_code < 500, (op.label, case.body, response.text[:300])
        missing = response.status_code == 404 and ("no run with id" in response.text
                                                    or "no study with id" in response.text)
        seen.setdefault(op.label, set()).add(0 if missing else response.status_code)

    follow()


def test_links_reach_every_operation_without_server_errors(tmp_path, small_cfg) -> None:
    """Every operation on a run or a study is reached through the OpenAPI links of the POST that made it:
    a run and a study are created with bodies schemathesis draws from the schema (until one is accepted),
    then each linked operation gets ``LINKED_EXAMPLES`` drawn cases with the link's parameters
    (``$response.body#/id``: the new id).  Each answers at least once about the resource that exists (not
    "no run/study with id"), and none with a 5xx.  The stand-in loop is quick (a run at speed 'max' ends at
    once: changes then answer 409), the study runner too."""
    s = Settings(data_dir=tmp_path / "data", max_duration_s=300.0, max_speed=50.0, max_concurrent_runs=4)
    app = create_app(s, small_cfg, loop_factory=FakeFactory(), study_runner=FakeStudyRunner())
    seen: dict[str, set[int]] = {}
    with ThreadedServer(app, free_port()) as srv:
        schema = schemathesis.openapi.from_url(f"{srv.url}/openapi.json")
        spec = schema.raw_schema
        ops = {r.ok().label: r.ok() for r in schema.get_all_operations()}
        with_id = [lbl for lbl in ops if "{run_id}" in lbl or "{study_id}" in lbl]
        assert len(with_id) >= 15, with_id  # the runs' and studies' operations of product.md
        for post in ("/api/runs", "/api/studies"):
            created = _create(ops[f"POST {post}"])
            links = _linked(spec, post)
            assert links, f"POST {post} has no links"
            for target, method, params in links.values():
                values = {k: created["id"] if v == "$response.body#/id" else v for k, v in params.items()}
                _follow(ops[f"{method.upper()} {target}"], values, seen)
    unreached = {lbl: seen.get(lbl) for lbl in with_id if not seen.get(lbl, set()) - {0}}
    assert not unreached, unreached
