"""``/api/placement``: where to put TC1-3 (issue 25, the paper's Remark 3), ``furnace-twin place-tcs`` for the
Studies view (:mod:`backend.studies.placement`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, HTTPException, Query, Request, status

from backend.api.deps import TokenDep
from backend.api.schemas import PlacementMap, PlacementOut, PlacementPaper, PlacementPosition, PlacementRequest
from backend.studies.placement import RANKED, PlacementJob, PlacementService

router = APIRouter(prefix="/api", tags=["placement"])


def _service(request: Request) -> PlacementService:
    service: PlacementService = request.app.state.placement
    return service


def placement_out(job: PlacementJob, furnace: str, count: int) -> PlacementOut:
    """The job as the API gives it: the first ``count`` positions of its ranking once done."""
    out = PlacementOut(furnace=furnace, oscillate=job.oscillate, state=job.state, count=count, seconds=job.seconds,
                       error=job.error)
    r = job.result
    if job.state != "done" or r is None:
        return out
    out.criterion = r["criterion"]
    out.positions = [PlacementPosition(rank=k + 1, **p) for k, p in enumerate(r["positions"][:count])]
    out.paper = PlacementPaper(positions=r["baseline"]["paper_positions"], score=r["baseline"]["paper"])
    rel = r["map"]["rel"]
    out.map = PlacementMap(x_rel=[p[0] for p in rel], y_rel=[p[1] for p in rel], score=r["map"]["score"])
    return out


@router.post("/placement", status_code=status.HTTP_202_ACCEPTED, response_model=PlacementOut,
             dependencies=[TokenDep])
def start_placement(request: Request, body: Annotated[PlacementRequest, Body()] = PlacementRequest(),
                    count: Annotated[int, Query(ge=1, le=RANKED, description="positions to give")] = 3,
                    ) -> PlacementOut:
    """Rank TC positions for the loaded furnace by the information they give about the fillet along the
    twin's nominal run (``furnace-twin place-tcs``), once per specimen mode and server: made in the background
    (5-30 s; ``state`` ``computing`` until then), read with ``GET /api/placement``."""
    job = _service(request).start(body.oscillate)
    return placement_out(job, request.app.state.manager.limits.furnace, count)


@router.get("/placement", response_model=PlacementOut,
            responses={404: {"description": "no ranking asked for in this mode yet: POST /api/placement"}})
def get_placement(request: Request,
                  oscillate: Annotated[bool, Query(description="the oscillating specimen's ranking")] = False,
                  count: Annotated[int, Query(ge=1, le=RANKED, description="positions to give")] = 3,
                  ) -> PlacementOut:
    """The ranking of one specimen mode: its best ``count`` positions (x, y, score), the paper's TC1-3 with
    their score, and the map of each candidate's score alone; ``computing`` or ``failed`` before."""
    job = _service(request).get(oscillate)
    if job is None:
        mode = "oscillating" if oscillate else "fixed"
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"no TC placement asked for the {mode} specimen yet: POST /api/placement")
    return placement_out(job, request.app.state.manager.limits.furnace, count)
