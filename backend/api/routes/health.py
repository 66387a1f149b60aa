"""``GET /api/health``: liveness, and whether the radiation model is ready (with its progress)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, HTTPException, Request, status

from backend.api.deps import ManagerDep, SettingsDep, TokenDep
from backend.api.schemas import Health, RadiationProgress

router = APIRouter(prefix="/api", tags=["health"])


@router.post("/radiation/retry", status_code=status.HTTP_202_ACCEPTED, response_model=RadiationProgress,
             dependencies=[TokenDep],
             responses={409: {"description": "the radiation model has not failed (it is loading or ready)"}})
def retry_radiation(manager: ManagerDep) -> RadiationProgress:
    """Load (or ray-trace) the radiation model again after it failed; ``GET /api/health`` follows it."""
    if not manager.retry_warm_up():
        w = manager.warm_up()
        state = "ready" if w is None else w.state
        raise HTTPException(status.HTTP_409_CONFLICT, f"the radiation model is {state}: nothing to retry")
    progress = _progress(manager.warm_up())
    assert progress is not None
    return progress


def _progress(w: Any) -> RadiationProgress | None:
    if w is None:
        return None
    remaining = w.remaining_s
    return RadiationProgress(stage=w.stage, done=w.done, total=w.total, fraction=w.fraction,
                             elapsed_s=round(w.elapsed_s, 2), error=w.error,
                             remaining_s=None if remaining is None else round(remaining, 1))


@router.get("/health", response_model=Health)
def health(manager: ManagerDep, settings: SettingsDep, request: Request) -> Health:
    w = manager.warm_up()
    progress = _progress(w)
    live = manager.live_runs()
    return Health(
        status="ok",
        radiation="ready" if w is None else w.state,
        radiation_progress=progress,
        active_runs=len(live),
        queued_runs=sum(manager.status(r) == "queued" for r in live),
        max_concurrent_runs=settings.max_concurrent_runs,
        viser_url=getattr(request.app.state, "viser_url", None),
        # the viewer as this server serves it, offline (backend/api/routes/rerun_page.py)
        rerun_url=f"{str(request.base_url).rstrip('/')}/rerun/" if getattr(request.app.state, "rerun_url", None)
        else None,
        auth_required=bool(settings.api_token),
        reads_need_token=settings.reads_need_token,
        disk=manager.disk.report(),
    )
