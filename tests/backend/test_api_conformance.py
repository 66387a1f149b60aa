"""The server says what its OpenAPI schema says, for the answers schemathesis' ``--checks all`` found wrong
(issue 23): a 405's ``Allow``, the 400 of an unreadable body, booleans and integers taken as the schema types
them, and a study's grid that lists exactly the paths the server takes (``backend/api/conformance.py``,
``backend/api/study_schema.py``).  The oracle is the served schema itself: each test reads it, then asks the
server, so a route added later is covered without editing these tests.
"""

from __future__ import annotations

import re
from functools import reduce
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError

from backend.app import create_app
from backend.core.settings import Settings
from conftest import FakeStudyRunner, fake_factory
from twin.scenario import Scenario
from twin.studies.spec import StudySpec

METHODS = ("get", "put", "post", "delete", "patch")


def client(tmp_path: Path, cfg) -> TestClient:
    s = Settings(data_dir=tmp_path / "data")
    app = create_app(s, cfg, loop_factory=fake_factory(), study_runner=FakeStudyRunner())
    return TestClient(app, base_url="http://127.0.0.1")


def concrete(template: str) -> str:
    """A request path for an OpenAPI path template: each ``{parameter}`` as a made-up id."""
    return re.sub(r"\{[^/]+\}", "x0", template)


def test_405_allow_names_every_documented_method_of_the_path(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg) as c:
        spec = c.get("/openapi.json").json()
        checked = 0
        for template, item in spec["paths"].items():
            documented = sorted(m.upper() for m in item if m in METHODS)
            r = c.request("PATCH" if "patch" not in item else "TRACE", concrete(template))
            assert r.status_code == 405, (template, r.status_code, r.text[:200])
            assert sorted(m.strip() for m in r.headers["allow"].split(",")) == documented, template
            checked += 1
        # a path with two methods, the case FastAPI's own 405 got wrong (it named only its first route's)
        assert sorted(spec["paths"]["/api/furnace/calibration"]) == ["delete", "get"]
        assert checked >= 25


def test_unreadable_body_is_a_documented_400(tmp_path, small_cfg) -> None:
    with client(tmp_path, small_cfg) as c:
        spec = c.get("/openapi.json").json()
        with_body = [(p, m) for p, item in spec["paths"].items() for m, op in item.items()
                     if m in METHODS and "requestBody" in op]
        assert len(with_body) >= 5
        for path, method in with_body:
            assert "400" in spec["paths"][path][method]["responses"], (method, path)
        r = c.post("/api/runs", content=b"\xff\xfe{", headers={"content-type": "application/json"})
        assert r.status_code == 400, r.text


@pytest.mark.parametrize("body", [{"oscillation": {"enabled": 0}}, {"oscillation": {"enabled": 1}},
                                  {"estimator": {"calibrate": 0}}, {"seed": 2.5}, {"seed": True}])
def test_run_body_types_are_the_schemas(tmp_path, small_cfg, body) -> None:
    """0 is not false and 2.5 is not an integer (the schema says boolean and integer; pydantic's lax mode took
    0 as false and schemathesis flagged the 2xx)."""
    with client(tmp_path, small_cfg) as c:
        r = c.post("/api/runs", json={"duration": 1.0, **body})
        assert r.status_code == 422, (body, r.status_code, r.text[:200])


def test_whole_float_is_an_integer_as_json_schema_counts_it() -> None:
    assert Scenario.model_validate({"seed": 2.0}).seed == 2
    assert isinstance(Scenario.model_validate({"seed": 2.0}).seed, int)


def test_study_refuses_null_fields_and_a_field_varied_with_one_inside_it() -> None:
    with pytest.raises(ValidationError, match="fields"):
        StudySpec.model_validate({"monte_carlo": {"n": 2, "fields": None}})
    with pytest.raises(ValidationError, match="a field inside it"):
        StudySpec.model_validate({"grid": {"oscillation": [{"enabled": True}], "oscillation.period": [20.0]}})
    assert StudySpec.model_validate({"monte_carlo": {"n": 2.0}}).monte_carlo.n == 2


def test_study_grid_schema_lists_the_paths_the_server_takes(tmp_path, small_cfg) -> None:
    """Every grid path the schema lists whose value the default scenario holds is accepted with that value by
    ``POST /api/studies/plan``; a path the schema does not list is refused there too."""
    default = Scenario().model_dump(mode="json")
    with client(tmp_path, small_cfg) as c:
        spec = c.get("/openapi.json").json()
        grid = spec["components"]["schemas"]["StudySpec"]["properties"]["grid"]
        assert grid["additionalProperties"] is False
        paths = list(grid["properties"])
        for expected in ("seed", "oscillation", "oscillation.period", "reference.t_E", "estimator.calibrate"):
            assert expected in paths, expected
        tried = 0
        for path in paths:
            try:
                value = reduce(lambda d, k: d[k], path.split("."), default)
            except (KeyError, TypeError):
                continue  # a field of a union member the default does not hold (a points reference's times)
            r = c.post("/api/studies/plan", json={"grid": {path: [value]}, "base": {"duration": 1.0}})
            assert r.status_code == 200, (path, value, r.text[:300])
            tried += 1
        assert tried >= 20
        assert "oscillation.perod" not in paths
        r = c.post("/api/studies/plan", json={"grid": {"oscillation.perod": [20.0]}})
        assert r.status_code == 422
