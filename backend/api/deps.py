"""Typed FastAPI dependencies: the run manager, the settings, the API-token check and the request
bodies checked against the loaded furnace (``twin.limits``)."""

from __future__ import annotations

import secrets
from collections.abc import Callable
from typing import Annotated, Any, TypeVar

from fastapi import Body, Depends, Header, HTTPException, Request, status
from fastapi.exceptions import RequestValidationError
from pydantic import SkipValidation, ValidationError

from backend.core.settings import Settings
from backend.runs.manager import RunManager
from backend.studies.manager import StudyManager
from twin.limits import ScenarioLimits
from twin.scenario import (
    FaultSpec,
    OscillationSpec,
    PointsReference,
    Reference,
    Scenario,
    TransitionReference,
    parse_faults,
    parse_oscillation,
    parse_reference,
    parse_scenario,
)

T = TypeVar("T")


def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def get_studies(request: Request) -> StudyManager:
    studies: StudyManager = request.app.state.studies
    return studies


def get_manager(request: Request) -> RunManager:
    manager: RunManager = request.app.state.manager
    return manager


def require_token(
    request: Request,
    authorization: Annotated[str | None, Header(description="'Bearer <token>' when a token is set")] = None,
    x_api_token: Annotated[str | None, Header(description="the API token, alternative header")] = None,
) -> None:
    """Mutating endpoints: when the server has an API token, the request must carry it."""
    expected = request.app.state.settings.api_token
    if not expected:
        return
    given = x_api_token
    if given is None and authorization and authorization.lower().startswith("bearer "):
        given = authorization[7:].strip()
    if given is None or not secrets.compare_digest(given.encode(), expected.encode()):
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "this server needs its API token: send 'Authorization: Bearer <token>' or 'X-API-Token'",
            headers={"WWW-Authenticate": "Bearer"},
        )


ManagerDep = Annotated[RunManager, Depends(get_manager)]
StudiesDep = Annotated[StudyManager, Depends(get_studies)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
TokenDep = Depends(require_token)


# ---- request bodies: documented by their model, validated against the loaded furnace ----
# FastAPI validates a body without context, so the models' furnace-dependent limits would be the
# default furnace's; SkipValidation hands the JSON over as sent and the dependency validates it
# with the server's limits (fields left out take this furnace's defaults).  Errors keep FastAPI's
# 422 shape, with the location under "body".


def _validated(parse: Callable[[Any, ScenarioLimits], T], body: Any, limits: ScenarioLimits) -> T:
    try:
        return parse(body, limits)
    except ValidationError as exc:
        errors = [{**e, "loc": ("body", *e["loc"])} for e in exc.errors(include_url=False)]
        raise RequestValidationError(errors, body=body) from None


def scenario_body(
    manager: ManagerDep,
    body: Annotated[Scenario | None, SkipValidation, Body(title="Scenario",
                                                         description="every field optional: GET /api/furnace "
                                                                     "has the limits and defaults")] = None,
) -> Scenario:
    return _validated(parse_scenario, body, manager.limits)


def reference_body(
    manager: ManagerDep, body: Annotated[Reference, SkipValidation, Body(title="Reference")],
) -> TransitionReference | PointsReference:
    return _validated(parse_reference, body, manager.limits)


def oscillation_body(
    manager: ManagerDep, body: Annotated[OscillationSpec, SkipValidation, Body(title="OscillationSpec")],
) -> OscillationSpec:
    return _validated(parse_oscillation, body, manager.limits)


def faults_body(
    manager: ManagerDep,
    body: Annotated[list[FaultSpec], SkipValidation, Body(title="Faults",
                                                          description="replaces the run's injected faults; "
                                                                      "'at' counts from now; [] clears them")],
) -> list[FaultSpec]:
    return _validated(parse_faults, body, manager.limits)


ScenarioBody = Annotated[Scenario, Depends(scenario_body)]
FaultsBody = Annotated[list[FaultSpec], Depends(faults_body)]
ReferenceBody = Annotated[TransitionReference | PointsReference, Depends(reference_body)]
OscillationBody = Annotated[OscillationSpec, Depends(oscillation_body)]
