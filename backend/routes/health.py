"""``GET /api/health``: liveness."""

from __future__ import annotations

from fastapi import APIRouter, Request

from backend.deps import ManagerDep, SettingsDep
from backend.schemas import Health

router = APIRouter(prefix="/api", tags=["health"])


@router.get("/health", response_model=Health)
def health(manager: ManagerDep, settings: SettingsDep, request: Request) -> Health:
    return Health(
        status="ok",
        active_runs=len(manager.live_runs()),
        max_concurrent_runs=settings.max_concurrent_runs,
        viser_url=getattr(request.app.state, "viser_url", None),
        auth_required=bool(settings.api_token),
        reads_need_token=settings.reads_need_token,
        disk=manager.disk.report(),
    )
