"""``GET /api/health``: liveness, and whether the radiation model is ready (with its progress)."""

from __future__ import annotations

from fastapi import APIRouter, Request

from backend.api.deps import ManagerDep, SettingsDep
from backend.api.schemas import Health, RadiationProgress

router = APIRouter(prefix="/api", tags=["health"])


@router.get("/health", response_model=Health)
def health(manager: ManagerDep, settings: SettingsDep, request: Request) -> Health:
    w = manager.warm_up()
    progress = None if w is None else RadiationProgress(
        stage=w.stage, done=w.done, total=w.total, fraction=w.fraction, elapsed_s=round(w.elapsed_s, 2), error=w.error)
    return Health(
        status="ok",
        radiation="ready" if w is None else w.state,
        radiation_progress=progress,
        active_runs=len(manager.live_runs()),
        max_concurrent_runs=settings.max_concurrent_runs,
        viser_url=getattr(request.app.state, "viser_url", None),
        rerun_url=getattr(request.app.state, "rerun_url", None),
        auth_required=bool(settings.api_token),
        reads_need_token=settings.reads_need_token,
        disk=manager.disk.report(),
    )
