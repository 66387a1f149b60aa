"""Typed FastAPI dependencies: the run manager, the repository and the API-token check."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends, Header, HTTPException, Request, status

from backend.repository import RunRepository
from backend.run_manager import RunManager
from backend.settings import Settings


def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def get_manager(request: Request) -> RunManager:
    manager: RunManager = request.app.state.manager
    return manager


def get_repo(request: Request) -> RunRepository:
    repo: RunRepository = request.app.state.repo
    return repo


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
RepoDep = Annotated[RunRepository, Depends(get_repo)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
TokenDep = Depends(require_token)
