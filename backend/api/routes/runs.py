"""``/api/runs``: start, list, inspect, stop, change reference / oscillation / injected faults, metrics."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Header, HTTPException, Query, Request, Response, status

from backend.api.deps import FaultsBody, ManagerDep, OscillationBody, ReferenceBody, ScenarioBody, TokenDep
from backend.api.schemas import (
    ChangeOut,
    ChangeResult,
    LabelIn,
    RunCreated,
    RunDetail,
    RunLinks,
    RunStoryOut,
    RunSummary,
    StopResult,
)
from backend.runs.manager import RunManager
from backend.runs.story import describe
from backend.storage.repository import ACTIVE_STATUSES, DEGRADED, RunRow
from twin.runs.metrics import windows_from

router = APIRouter(prefix="/api/runs", tags=["runs"])


def links(run_id: str, rerun: str | None = None) -> RunLinks:
    base = f"/api/runs/{run_id}"
    return RunLinks(self=base, stream=f"{base}/stream", metrics=f"{base}/metrics",
                    recording=f"{base}/recording", timeseries=f"{base}/timeseries", faults=f"{base}/faults",
                    rerun=rerun)


def rerun_link(request: Request | None, manager: RunManager, run_id: str, state: str) -> str | None:
    """The rerun web viewer served by this server (``/rerun/``, offline) on a run: its live stream while it goes,
    else its recording file (a URL ending ``.rrd``, which the viewer needs to open it)."""
    viewer = None if request is None else getattr(request.app.state, "rerun_viewer", None)
    if viewer is None or request is None:
        return None
    base = str(request.base_url).rstrip("/")
    page = f"{base}/rerun/"
    if (state in ACTIVE_STATUSES or manager.status(run_id) is not None) and manager.live_url:
        return str(viewer.link(manager.live_url, page=page))
    return str(viewer.link(f"{base}/api/runs/{run_id}/recording.rrd", page=page))


def scenario_summary(scenario: dict[str, Any]) -> dict[str, Any]:
    """A scenario for lists: a points reference as its count, last time and last temperature (a list of
    runs stays small however long their point lists are; ``GET /api/runs/{id}`` has the whole scenario)."""
    ref = scenario.get("reference") or {}
    pts = ref.get("points")
    if not isinstance(pts, list) or not pts:
        return scenario
    return {**scenario, "reference": {"points": len(pts), "t_E": pts[-1][0], "setpoint": pts[-1][1]}}


def live_reason(manager: RunManager, run_id: str, state: str) -> str | None:
    """Why a run this server drives is in ``state``: why it ended, once it has (the database may not hold the
    reason yet while the run is let go); while it goes degraded, since when no thermocouple reading reaches its
    estimate."""
    ended = manager.ending_reason(run_id)
    if ended is not None:
        return ended
    sample = manager.latest(run_id) if state == DEGRADED else None
    since = getattr(sample.snapshot, "blind_since", None) if sample is not None else None
    return None if since is None else f"blind since t = {since:.1f} s: no thermocouple reading reaches the estimate"


def summary(row: RunRow, manager: RunManager, *, whole: bool = True, request: Request | None = None) -> RunSummary:
    state = manager.status(row.id) or row.status
    files = manager.files(row.id)
    return RunSummary(
        id=row.id,
        status=state,
        status_reason=row.status_reason if manager.status(row.id) is None else live_reason(manager, row.id, state),
        created_at=row.created_at,
        started_at=row.started_at,
        ended_at=row.ended_at,
        scenario=row.scenario if whole else scenario_summary(row.scenario),
        latest=row.latest,
        metrics=row.metrics,
        error=row.error,
        label=row.label,
        story=RunStoryOut(**describe(row.scenario, manager.changes(row.id)).to_json()),
        files={"recording": files.recording.is_file(), "timeseries": files.timeseries.is_file(),
               "metrics": files.metrics.is_file()},
        links=links(row.id, rerun_link(request, manager, row.id, state)),
    )


@router.post("", status_code=status.HTTP_201_CREATED, response_model=RunCreated, dependencies=[TokenDep],
             responses={200: {"description": "a repeated Idempotency-Key: the run the first request started"},
                        409: {"description": "the Idempotency-Key was used for another scenario, or another run "
                                             "already drives that furnace"},
                        422: {"description": "invalid scenario, over the furnace's or the server's limits, a "
                                             "reference this furnace cannot follow by a wide margin, or a "
                                             "furnace over OPC UA it may not or cannot reach"},
                        429: {"description": "too many runs at once"}})
async def start_run(
    manager: ManagerDep, scenario: ScenarioBody, response: Response,
    idempotency_key: Annotated[str | None, Header(max_length=100, description="a client's id for this start: the "
                                                  "same id again returns the same run instead of a second one")] = None,
) -> RunCreated:
    """Start a closed-loop run of the scenario (every field has a default: the furnace's, see
    ``GET /api/furnace``). 201 with the run id and what the feasibility check warns about."""
    started = await manager.launch(scenario, idempotency_key)
    if started.replayed:
        response.status_code = status.HTTP_200_OK
    return RunCreated(id=started.run_id, status=manager.status(started.run_id) or manager.run(started.run_id).status,
                      links=links(started.run_id), warnings=list(started.warnings), replayed=started.replayed)


@router.get("", response_model=list[RunSummary])
def list_runs(manager: ManagerDep, request: Request,
              limit: Annotated[int, Query(ge=1, le=1000)] = 200) -> list[RunSummary]:
    """All runs, newest first; a points reference is summarised as ``{"points": count, "t_E", "setpoint"}``."""
    return [summary(r, manager, whole=False, request=request) for r in manager.runs(limit)]


@router.get("/{run_id}", response_model=RunDetail, responses={404: {"description": "no such run"}})
def get_run(run_id: str, manager: ManagerDep, request: Request) -> RunDetail:
    """One run: status, scenario, the reference and oscillation in force, latest values, metrics,
    the changes made while it ran."""
    row = manager.run(run_id)
    now = manager.in_force(row.id)
    changes = manager.changes(row.id)
    ref = row.scenario.get("reference") or {}
    end = (ref["points"][-1][0], ref["points"][-1][1]) if "points" in ref else (ref.get("t_E"), ref.get("setpoint"))
    windows = None if end[0] is None or end[1] is None else windows_from(  # as the metrics count them
        float(end[0]), float(end[1]),
        ((c.applied_t, c.kind, c.body) for c in changes if c.status == "applied" and c.applied_t is not None))
    return RunDetail(
        **summary(row, manager, request=request).model_dump(),
        reference=now.reference,
        oscillation=now.oscillation,
        faults=now.faults,
        fault_events=manager.fault_events(row.id),
        changes=[ChangeOut(**c.__dict__) for c in changes],
        windows=None if windows is None else windows.to_json(),
    )


@router.patch("/{run_id}", response_model=RunSummary, dependencies=[TokenDep],
              responses={404: {"description": "no such run"}, 422: {"description": "label too long"}})
def label_run(run_id: str, manager: ManagerDep, body: LabelIn) -> RunSummary:
    """Name the run (``{"label": "fixed, TC4 middle"}``; null or empty removes the name)."""
    return summary(manager.set_label(run_id, body.label), manager)


@router.delete("/{run_id}", status_code=status.HTTP_204_NO_CONTENT, dependencies=[TokenDep],
               responses={404: {"description": "no such run"}, 409: {"description": "the run is still going"}})
def delete_run(run_id: str, manager: ManagerDep) -> Response:
    """Delete a run that has ended, with its files (recording, time series, metrics); a running run is a 409."""
    manager.delete(run_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post("/{run_id}/stop", response_model=StopResult, status_code=status.HTTP_202_ACCEPTED,
             dependencies=[TokenDep],
             responses={404: {"description": "no such run"}, 409: {"description": "the run has ended"}})
def stop_run(run_id: str, manager: ManagerDep) -> StopResult:
    """Stop the run at its next sample; its data so far stays."""
    manager.stop(run_id)
    return StopResult(id=run_id, status="stopping")


CHANGE_RESPONSES: dict[int | str, dict[str, Any]] = {
    202: {"model": ChangeResult, "description": "still being planned: the outcome comes in the events"},
    404: {"description": "no such run"}, 409: {"description": "the run has ended (or ended before the change)"},
}


def _change_result(result: dict[str, Any], response: Response) -> ChangeResult:
    if result["status"] == "pending":
        response.status_code = status.HTTP_202_ACCEPTED
    return ChangeResult(**result)


@router.put("/{run_id}/reference", response_model=ChangeResult, dependencies=[TokenDep],
            responses={**CHANGE_RESPONSES,
                       422: {"description": "invalid or unreachable reference, a plan beyond the server's time "
                                            "or memory, or a failed re-plan (nothing applied)"}})
async def change_reference(run_id: str, manager: ManagerDep, reference: ReferenceBody,
                           response: Response) -> ChangeResult:
    """New reference (setpoint and t_E, or points); the feedforward is re-planned from the estimate.

    The answer comes when the new plan is in force (status 'applied', from ``applied_t``), when a later
    reference change replaced this one before it was planned ('superseded'), or, after the server's wait
    limit, as 202 'pending' (the outcome then comes in the events).  A change that cannot be planned
    is a 422 that says why; the run goes on with what it had.
    """
    manager.run(run_id)
    return _change_result(await manager.change(run_id, "reference", reference), response)


@router.put("/{run_id}/oscillation", response_model=ChangeResult, dependencies=[TokenDep],
            responses={**CHANGE_RESPONSES,
                       422: {"description": "invalid, an amplitude above the furnace's eta_max, or a re-plan "
                                            "that cannot be made (nothing applied)"}})
async def change_oscillation(run_id: str, manager: ManagerDep, oscillation: OscillationBody,
                             response: Response) -> ChangeResult:
    """Switch the oscillation on or off (and its amplitude, period); models and gains switch.
    A field left out takes the furnace's default (``GET /api/furnace``), not the run's current value."""
    manager.run(run_id)
    return _change_result(await manager.change(run_id, "oscillation", oscillation), response)


@router.put("/{run_id}/faults", response_model=ChangeResult, dependencies=[TokenDep],
            responses={**CHANGE_RESPONSES,
                       422: {"description": "invalid faults, or a furnace that takes none (a real one)"}})
async def change_faults(run_id: str, manager: ManagerDep, faults: FaultsBody, response: Response) -> ChangeResult:
    """Replace the faults injected into the run's simulated furnace: TC1..TC4 stuck, drift (K/s), offset (K),
    dropout; a lamp group failed or derated (fraction kept).  Each ``at`` counts from now; ``[]`` clears them.
    The twin is not told: it must find them in its own data (the run's events and ``fault_events``)."""
    manager.run(run_id)
    return _change_result(await manager.change(run_id, "faults", faults), response)


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
