"""``/api/runs/{id}/recording`` and ``/timeseries``: a run's own files, nothing else."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, status
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from backend.deps import ManagerDep
from backend.series import load_series
from twin.runs.series_store import has_parts, snapshot_file

router = APIRouter(prefix="/api/runs", tags=["files"])


def _file(run_id: str, manager: ManagerDep, which: str) -> Path:
    manager.run(run_id)  # 404 unless the id comes from the database, before it names a folder
    files = manager.files(run_id)
    path: Path = getattr(files, which)
    if which == "timeseries" and has_parts(files.folder):  # a run in progress: its parts so far, as one file
        return snapshot_file(files.folder, path)
    if not path.is_file():
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"run {run_id} has no {path.name} (yet)")
    return path


@router.get("/{run_id}/recording", response_class=FileResponse,
            responses={200: {"content": {"application/octet-stream": {}}},
                       404: {"description": "no such run or no recording"}})
def recording(run_id: str, manager: ManagerDep) -> FileResponse:
    """The rerun recording (``.rrd``); open it with ``rerun FILE``."""
    path = _file(run_id, manager, "recording")
    return FileResponse(path, media_type="application/octet-stream", filename=f"{run_id}-recording.rrd")


@router.get("/{run_id}/timeseries", response_class=FileResponse,
            responses={200: {"content": {"application/octet-stream": {}}},
                       404: {"description": "no such run or no time series"}})
def timeseries(run_id: str, manager: ManagerDep) -> FileResponse:
    """The raw time series (``.npz``, layout in product.md), flushed every few seconds while running."""
    path = _file(run_id, manager, "timeseries")
    cleanup = BackgroundTask(path.unlink, missing_ok=True) if path.name.startswith(".timeseries-") else None
    return FileResponse(path, media_type="application/octet-stream", filename=f"{run_id}-timeseries.npz",
                        background=cleanup)


@router.get("/{run_id}/series", responses={404: {"description": "no such run or no time series yet"}})
def series(run_id: str, manager: ManagerDep,
           max_points: Annotated[int, Query(ge=10, le=20000)] = 2000) -> dict[str, Any]:
    """The stored time series as JSON (decimated to ``max_points``) for charts of any run."""
    path = _file(run_id, manager, "timeseries")
    try:
        return load_series(path, max_points)
    except (OSError, ValueError, KeyError) as exc:  # e.g. a file from an older layout
        raise HTTPException(status.HTTP_409_CONFLICT, f"run {run_id}: cannot read {path.name}: {exc}") from None
    finally:
        if path.name.startswith(".timeseries-"):
            path.unlink(missing_ok=True)
