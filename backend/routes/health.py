"""``GET /api/health`` (liveness) and ``GET /api/furnace`` (what the dashboard draws)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from backend.deps import ManagerDep, SettingsDep
from backend.schemas import Health

router = APIRouter(prefix="/api", tags=["health"])


@router.get("/health", response_model=Health)
def health(manager: ManagerDep, settings: SettingsDep, request: Request) -> Health:
    return Health(
        status="ok",
        active_runs=len(manager.active),
        max_concurrent_runs=settings.max_concurrent_runs,
        viser_url=getattr(request.app.state, "viser_url", None),
        auth_required=bool(settings.api_token),
    )


@router.get("/furnace")
def furnace(manager: ManagerDep) -> dict[str, Any]:
    """Specimen size (m), FD grid, fillet (x0, x1, y0, y1 in m), TC positions (m), lamp groups."""
    cfg = manager.cfg
    s = cfg.specimen
    return {
        "L_s": s.length,
        "W_s": s.width,
        "nx": s.nx,
        "ny": s.ny,
        "x": [(i + 0.5) * s.length / s.nx for i in range(s.nx)],
        "y": [(j + 0.5) * s.width / s.ny for j in range(s.ny)],
        "fillet": list(cfg.fillet),
        "tc_relative": [list(p) for p in cfg.sensors.relative_positions],
        "groups": [g.name for g in cfg.lamps.groups],
        "t_s": cfg.sampling.t_s,
        "eta_max": cfg.oscillation.eta_max,
    }
