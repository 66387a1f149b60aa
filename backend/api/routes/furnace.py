"""``GET /api/furnace``: the loaded furnace, what the dashboard draws and every scenario limit and default."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from backend.api.deps import ManagerDep, ScenarioBody, TokenDep
from backend.api.schemas import FurnaceOut, LampGroupOut
from twin.physics.fillet import fillet_box
from twin.physics.grid import cell_centers
from twin.scenario import parse_scenario

router = APIRouter(prefix="/api", tags=["furnace"])


@router.get("/furnace", response_model=FurnaceOut)
def furnace(manager: ManagerDep) -> FurnaceOut:
    """Name, geometry summary, TC positions, lamp groups, and the scenario limits and defaults
    (``twin.limits``: the furnace's, within this server's run length and speed)."""
    cfg, limits = manager.cfg, manager.limits
    s, lamps = cfg.specimen, cfg.lamps
    x, y = cell_centers(cfg)
    return FurnaceOut(
        name=limits.furnace,
        L_s=s.length, W_s=s.width, B_s=s.thickness, nx=s.nx, ny=s.ny,
        x=x.tolist(), y=y.tolist(),
        fillet=list(fillet_box(s.length, s.width)),
        eta_max=cfg.oscillation.eta_max,
        t_s=cfg.sampling.t_s,
        lamps={side: {"count": a.count, "pitch": a.pitch, "distance": a.distance}
               for side, a in (("horizontal", lamps.horizontal), ("vertical", lamps.vertical))},
        tc_relative=[list(p) for p in cfg.sensors.relative_positions],
        tc_positions=[list(p) for p in cfg.tc_positions()],
        calibration_bounds={name: list(getattr(cfg.calibration.bounds, name)) for name in
                            ("lamp_efficiency", "emissivity", "convection")},
        groups=[LampGroupOut(name=g.name, lamps=list(g.lamps)) for g in lamps.groups],
        limits=limits.to_json(),
        defaults=parse_scenario({}, limits).model_dump(mode="json"),
    )


@router.post("/feasibility", responses={422: {"description": "the scenario itself is invalid"}})
async def feasibility(manager: ManagerDep, scenario: ScenarioBody) -> dict[str, Any]:
    """Would ``POST /api/runs`` start this scenario, and can the furnace follow its reference?
    ``verdict``: ``ok``, ``warn`` (starts; ``messages`` say when and by how much the fillet mean falls
    behind), ``refuse`` (a 422 on start) or ``pending`` (the radiation model is still loading: only the limits
    were checked, a run would wait as ``queued``); ``best``: the closest fillet mean the furnace can reach
    (``t``, ``T``); ``hold_range``: the means it can hold (lamps off, full power) in K.  Nothing is started."""
    return await manager.checks.preview(manager.with_memory(scenario))


def _calibration(manager: Any) -> dict[str, Any]:
    from twin.control.calibration_memory import memories

    return {"furnace": manager.limits.furnace,
            "plants": [m.load() for m in memories(manager.settings.data_dir, manager.cfg)]}


@router.get("/furnace/calibration")
def calibration(manager: ManagerDep) -> dict[str, Any]:
    """What the twin has learnt about this furnace from earlier runs, per plant it ran on (simulated with its
    truth and mismatch, or an OPC UA endpoint): each parameter's relative deviation ``value``, ``sigma``,
    ``when`` and the ``runs`` it came from.  The next run's plan and its feasibility check start from these
    (docs/control.md)."""
    return _calibration(manager)


@router.delete("/furnace/calibration", dependencies=[TokenDep])
def reset_calibration(manager: ManagerDep) -> dict[str, Any]:
    """Forget what the twin has learnt about this furnace: the next run plans with the nominal model."""
    from twin.control.calibration_memory import memories

    for m in memories(manager.settings.data_dir, manager.cfg):
        m.reset()
    return _calibration(manager)
