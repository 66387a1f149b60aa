"""``/api/runs``: start, list, inspect, stop, change reference / oscillation, metrics."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, HTTPException, Query, status

from backend.deps import ManagerDep, RepoDep, TokenDep
from backend.repository import RunRow
from backend.run_manager import RunManager
from backend.schemas import ChangeOut, ChangeResult, RunCreated, RunDetail, RunLinks, RunSummary, StopResult
from twin.scenario import OscillationSpec, Reference, Scenario

router = APIRouter(prefix="/api/runs", tags=["runs"])
DEFAULT_SCENARIO = Scenario.model_validate({})


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


def _row(repo: RepoDep, run_id: str) -> RunRow:
    row = repo.get(run_id)
    if row is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no run with id {run_id!r}")
    return row


@router.post("", status_code=status.HTTP_201_CREATED, response_model=RunCreated, dependencies=[TokenDep],
             responses={422: {"description": "invalid scenario, over the server's limits, or a furnace it may "
                                              "not or cannot reach"},
                        409: {"description": "another run already drives that furnace"},
                        429: {"description": "too many runs at once"}})
async def start_run(manager: ManagerDep, scenario: Annotated[Scenario, Body()] = DEFAULT_SCENARIO) -> RunCreated:
    """Start a closed-loop run of the scenario (every field has a default). 201 with the run id."""
    run_id = await manager.start(scenario)
    return RunCreated(id=run_id, status=manager.status(run_id) or "queued", links=links(run_id))


@router.get("", response_model=list[RunSummary])
def list_runs(manager: ManagerDep, repo: RepoDep,
              limit: Annotated[int, Query(ge=1, le=1000)] = 200) -> list[RunSummary]:
    """All runs, newest first."""
    return [summary(r, manager) for r in repo.list_runs(limit)]


@router.get("/{run_id}", response_model=RunDetail, responses={404: {"description": "no such run"}})
def get_run(run_id: str, manager: ManagerDep, repo: RepoDep) -> RunDetail:
    """One run: status, scenario, latest values, metrics, the changes made while it ran."""
    row = _row(repo, run_id)
    files = manager.files(row.id)
    return RunDetail(
        **summary(row, manager).model_dump(),
        changes=[ChangeOut(**c.__dict__) for c in repo.changes(row.id)],
        files={"recording": files.recording.is_file(), "timeseries": files.timeseries.is_file(),
               "metrics": files.metrics.is_file()},
    )


@router.post("/{run_id}/stop", response_model=StopResult, status_code=status.HTTP_202_ACCEPTED,
             dependencies=[TokenDep],
             responses={404: {"description": "no such run"}, 409: {"description": "the run has ended"}})
def stop_run(run_id: str, manager: ManagerDep, repo: RepoDep) -> StopResult:
    """Stop the run at its next sample; its data so far stays."""
    _row(repo, run_id)
    manager.stop(run_id)
    return StopResult(id=run_id, status="stopping")


@router.put("/{run_id}/reference", response_model=ChangeResult, dependencies=[TokenDep],
            responses={404: {"description": "no such run"}, 409: {"description": "the run has ended"},
                       422: {"description": "invalid or unreachable reference"}})
async def change_reference(
    run_id: str, manager: ManagerDep, repo: RepoDep,
    reference: Annotated[Reference, Body()],
) -> ChangeResult:
    """New reference (setpoint and t_E, or points); the feedforward is re-planned from the estimate.

    Applied at the next sample; the response comes when the re-plan is done (status
    'applied'), or after the server's wait limit with status 'pending'.
    """
    _row(repo, run_id)
    return ChangeResult(**await manager.change(run_id, "reference", reference))


@router.put("/{run_id}/oscillation", response_model=ChangeResult, dependencies=[TokenDep],
            responses={404: {"description": "no such run"}, 409: {"description": "the run has ended"}})
async def change_oscillation(
    run_id: str, manager: ManagerDep, repo: RepoDep, oscillation: Annotated[OscillationSpec, Body()],
) -> ChangeResult:
    """Switch the oscillation on or off (and its amplitude, period); models and gains switch."""
    _row(repo, run_id)
    return ChangeResult(**await manager.change(run_id, "oscillation", oscillation))


@router.get("/{run_id}/metrics", response_model=dict[str, float | None],
            responses={404: {"description": "no such run"},
                       409: {"description": "no metrics yet (the run is going or ended before any sample)"}})
def get_metrics(run_id: str, manager: ManagerDep, repo: RepoDep) -> dict[str, float | None]:
    """The run's metrics (product.md); windows the run did not reach are null."""
    row = _row(repo, run_id)
    if row.metrics is None:
        state = manager.status(run_id) or row.status
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"run {run_id} has no metrics (status {state}); they are computed when it ends")
    return row.metrics
