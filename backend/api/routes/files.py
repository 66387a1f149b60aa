"""``/api/runs/{id}/recording`` and ``/timeseries``: a run's own files, nothing else."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Request, status
from fastapi.responses import FileResponse, Response
from starlette.background import BackgroundTask

from backend.api.deps import ManagerDep
from backend.streaming.series import NoSeries, run_arrays, series_json
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


@router.get("/{run_id}/recording.rrd", response_class=FileResponse,
            responses={200: {"content": {"application/octet-stream": {}}},
                       404: {"description": "no such run or no recording"}})
def recording_rrd(run_id: str, manager: ManagerDep, request: Request) -> FileResponse:
    """The same recording under a name ending ``.rrd``: what the rerun viewer needs to open it (``links.rerun``)."""
    return recording(run_id, manager, request)


@router.get("/{run_id}/recording", response_class=FileResponse,
            responses={200: {"content": {"application/octet-stream": {}}},
                       404: {"description": "no such run or no recording"}})
def recording(run_id: str, manager: ManagerDep, request: Request) -> FileResponse:
    """The rerun recording (``.rrd``); open it with ``rerun FILE``, or in the server's rerun web viewer
    (the run's ``links.rerun``: this file is readable from the viewer's origin)."""
    path = _file(run_id, manager, "recording")
    # a copy: the recording may still grow (rerun appends while the run or its sink is going), and a file that
    # grows while it is sent gives more bytes than its Content-Length (the client sees a broken response)
    fd, name = tempfile.mkstemp(prefix=".recording-", suffix=".rrd", dir=path.parent)
    with os.fdopen(fd, "wb") as out, path.open("rb") as src:
        shutil.copyfileobj(src, out)
    copy = Path(name)
    response = FileResponse(copy, media_type="application/octet-stream", filename=f"{run_id}-recording.rrd",
                            background=BackgroundTask(copy.unlink, missing_ok=True))
    origin = request.headers.get("origin")
    if origin is not None and origin in viewer_origins(request):
        response.headers["Access-Control-Allow-Origin"] = origin
        response.headers["Vary"] = "Origin"
    return response


def viewer_origins(request: Request) -> set[str]:
    """The origins of the server's rerun web viewer (loopback by name and by address)."""
    viewer = getattr(request.app.state, "rerun_viewer", None)
    if viewer is None:
        return set()
    return {f"http://127.0.0.1:{viewer.web_port}", f"http://localhost:{viewer.web_port}"}


@router.get("/{run_id}/timeseries", response_class=FileResponse,
            responses={200: {"content": {"application/octet-stream": {}}},
                       404: {"description": "no such run or no time series"}})
def timeseries(run_id: str, manager: ManagerDep) -> FileResponse:
    """The raw time series (``.npz``, layout in product.md), flushed every few seconds while running."""
    path = _file(run_id, manager, "timeseries")
    cleanup = BackgroundTask(path.unlink, missing_ok=True) if path.name.startswith(".timeseries-") else None
    return FileResponse(path, media_type="application/octet-stream", filename=f"{run_id}-timeseries.npz",
                        background=cleanup)


@router.get("/{run_id}/series", response_class=Response,
            responses={200: {"content": {"application/json": {}}},
                       404: {"description": "no such run or no time series yet"}})
def series(run_id: str, manager: ManagerDep,
           max_points: Annotated[int, Query(ge=10, le=20000)] = 2000) -> Response:
    """The run's time series so far as JSON (decimated to ``max_points``) for charts of any run: a running
    run's up to its latest sample, with every event, the live changes and the metric windows
    (``backend.streaming.series``)."""
    try:  # serialised here, in the worker thread: a big answer never holds up the event loop (the streams)
        body = json.dumps(series_json(run_arrays(manager, run_id), max_points), allow_nan=False,
                          separators=(",", ":"))
        return Response(body, media_type="application/json")
    except NoSeries as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(exc)) from None
    except (OSError, ValueError, KeyError) as exc:  # e.g. a file from an older layout
        raise HTTPException(status.HTTP_409_CONFLICT, f"run {run_id}: cannot read its time series: {exc}") from None
