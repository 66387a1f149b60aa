"""``/api/runs``: start, list, inspect, stop, change reference / oscillation, metrics."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, status

from backend.deps import ManagerDep, OscillationBody, ReferenceBody, ScenarioBody, TokenDep
from backend.repository import RunRow
from backend.run_manager import RunManager
from backend.schemas import ChangeOut, ChangeResult, RunCreated, RunDetail, RunLinks, RunSummary, StopResult

router = APIRouter(prefix="/api/runs", tags=["runs"])


def links(run_id: str) -> RunLinks:
    base = f"/api/runs/{run_id}"
    return RunLinks(self=base, stream=f"{base}/stream", metrics=f"{base}/metrics",
                    recording=f"{base}/recording", timeseries=f"{base}/timeseries")


def summary(row: RunRow, manager: RunManager) -> RunSummary:
    return RunSummary(
        id=row.id,
        status=manager.status(row.id) or row.status,
        created_at=row.created_at,
        started_at=row.started_at,
        ended_at=row.ended_at,
        scenario=row.scenario,
        latest=row.latest,
        metrics=row.metrics,
        error=row.error,
        links=links(row.id),
    )


@router.post("", status_code=status.HTTP_201_CREATED, response_model=RunCreated, dependencies=[TokenDep],
             responses={422: {"description": "invalid scenario, or over the furnace's or the server's limits"},
                        429: {"description": "too many runs at once"}})
async def start_run(manager: ManagerDep, scenario: ScenarioBody) -> RunCreated:
    """Start a closed-loop run of the scenario (every field has a default: the furnace's, see
    ``GET /api/furnace``). 201 with the run id."""
    run_id = await manager.start(scenario)
    return RunCreated(id=run_id, status=manager.status(run_id) or "queued", links=links(run_id))


@router.get("", response_model=list[RunSummary])
def list_runs(manager: ManagerDep, limit: Annotated[int, Query(ge=1, le=1000)] = 200) -> list[RunSummary]:
    """All runs, newest first."""
    return [summary(r, manager) for r in manager.runs(limit)]


@router.get("/{run_id}", response_model=RunDetail, responses={404: {"description": "no such run"}})
def get_run(run_id: str, manager: ManagerDep) -> RunDetail:
    """One run: status, scenario, the reference and oscillation in force, latest values, metrics,
    the changes made while it ran."""
    row = manager.run(run_id)
    files = manager.files(row.id)
    now = manager.in_force(row.id)
    return RunDetail(
        **summary(row, manager).model_dump(),
        reference=now.reference,
        oscillation=now.oscillation,
        changes=[ChangeOut(**c.__dict__) for c in manager.changes(row.id)],
        files={"recording": files.recording.is_file(), "timeseries": files.timeseries.is_file(),
               "metrics": files.metrics.is_file()},
    )


@router.post("/{run_id}/stop", response_model=StopResult, status_code=status.HTTP_202_ACCEPTED,
             dependencies=[TokenDep],
             responses={404: {"description": "no such run"}, 409: {"description": "the run has ended"}})
def stop_run(run_id: str, manager: ManagerDep) -> StopResult:
    """Stop the run at its next sample; its data so far stays."""
    manager.stop(run_id)
    return StopResult(id=run_id, status="stopping")


@router.put("/{run_id}/reference", response_model=ChangeResult, dependencies=[TokenDep],
            responses={404: {"description": "no such run"}, 409: {"description": "the run has ended"},
                       422: {"description": "invalid or unreachable reference"}})
async def change_reference(run_id: str, manager: ManagerDep, reference: ReferenceBody) -> ChangeResult:
    """New reference (setpoint and t_E, or points); the feedforward is re-planned from the estimate.

    Applied at the next sample; the response comes when the re-plan is done (status
    'applied'), or after the server's wait limit with status 'pending'.
    """
    manager.run(run_id)
    return ChangeResult(**await manager.change(run_id, "reference", reference))


@router.put("/{run_id}/oscillation", response_model=ChangeResult, dependencies=[TokenDep],
            responses={404: {"description": "no such run"}, 409: {"description": "the run has ended"},
                       422: {"description": "invalid, or an amplitude above the furnace's eta_max"}})
async def change_oscillation(run_id: str, manager: ManagerDep, oscillation: OscillationBody) -> ChangeResult:
    """Switch the oscillation on or off (and its amplitude, period); models and gains switch.
    A field left out takes the furnace's default (``GET /api/furnace``), not the run's current value."""
    manager.run(run_id)
    return ChangeResult(**await manager.change(run_id, "oscillation", oscillation))


@router.get("/{run_id}/metrics", response_model=dict[str, Any],
            responses={404: {"description": "no such run"},
                       409: {"description": "no metrics yet (the run is going or ended before any sample)"}})
def get_metrics(run_id: str, manager: ManagerDep) -> dict[str, Any]:
    """The run's metrics (product.md); windows the run did not reach are null."""
    row = manager.run(run_id)
    if row.metrics is None:
        state = manager.status(run_id) or row.status
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"run {run_id} has no metrics (status {state}); they are computed when it ends")
    return row.metrics
