"""``/api/runs/{id}/export.csv`` and ``/report.pdf`` / ``/report.png``: a run's series and a one-page report,
for a running run up to its latest sample."""

from __future__ import annotations

import csv
import io
import re
import time
from collections.abc import Iterator, Mapping
from importlib import metadata
from typing import Any, Literal

import numpy as np
from fastapi import APIRouter, HTTPException, status
from fastapi.responses import Response, StreamingResponse
from starlette.concurrency import run_in_threadpool

from backend.api.deps import ManagerDep
from backend.runs.story import RunStory, describe
from backend.storage.repository import ACTIVE_STATUSES
from backend.streaming.series import NoSeries, fillet_series, run_arrays
from twin.experiments.report import write_report
from twin.runs.metrics import compute_metrics

router = APIRouter(prefix="/api/runs", tags=["exports"])
NOT_FOUND: dict[int | str, dict[str, Any]] = {404: {"description": "no such run, or no samples yet"}}


def _arrays(manager: ManagerDep, run_id: str) -> Mapping[str, Any]:
    try:
        return run_arrays(manager, run_id)
    except NoSeries as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(exc)) from None
    except (OSError, ValueError, KeyError) as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, f"run {run_id}: cannot read its time series: {exc}") from None


def csv_columns(z: Mapping[str, Any]) -> tuple[list[str], np.ndarray]:
    """Column names (with units) and the (n, k) table of every sample: time, eta, reference, fillet mean,
    TC readings and estimates, group powers and feedforward, T_sup and spread (where the field is stored)."""
    t = np.asarray(z["t"], float)
    n = len(t)
    groups = [str(g) for g in np.asarray(z.get("group_names", [])).ravel()] or [f"g{j + 1}" for j in range(6)]
    cols: list[tuple[str, np.ndarray]] = [("t_s", t), ("eta_m", np.asarray(z["eta"], float)),
                                          ("T_ref_K", np.asarray(z["T_ref"], float)),
                                          ("T_mean_hat_K", np.asarray(z["T_mean_hat"], float))]
    tc, tc_hat = np.asarray(z["tc"], float).reshape(n, -1), np.asarray(z["tc_hat"], float).reshape(n, -1)
    cols += [(f"TC{i + 1}_K", tc[:, i]) for i in range(tc.shape[1])]
    cols += [(f"TC{i + 1}_hat_K", tc_hat[:, i]) for i in range(tc_hat.shape[1])]
    for key in ("u", "u_ff"):
        a = np.asarray(z[key], float).reshape(n, -1)
        cols += [(f"{key}_{groups[j] if j < len(groups) else j + 1}", a[:, j]) for j in range(a.shape[1])]
    tf, sup, spread = fillet_series(z)
    if tf.size == n and n:  # fields at every sample (the loop's record)
        cols += [("T_sup_K", sup), ("spread_K", spread)]
    return [c[0] for c in cols], np.column_stack([c[1] for c in cols]) if n else np.zeros((0, len(cols)))


def _csv_rows(names: list[str], table: np.ndarray) -> Iterator[str]:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(names)
    for k in range(0, len(table), 500):
        for row in table[k:k + 500]:
            writer.writerow(["" if not np.isfinite(v) else f"{v:.6g}" for v in row])
        yield buf.getvalue()
        buf.seek(0)
        buf.truncate()
    yield buf.getvalue()


def _story(manager: ManagerDep, run_id: str) -> RunStory:
    return describe(manager.run(run_id).scenario, manager.changes(run_id))


def _filename(manager: ManagerDep, run_id: str, suffix: str) -> str:
    """ "osc-48-mm-18-s-<id>.pdf": the run's label (else its automatic one) first, then its id."""
    label = manager.run(run_id).label or _story(manager, run_id).auto_label
    safe = re.sub(r"[^A-Za-z0-9._-]+", "-", label).strip("-")[:40]
    return f"{safe + '-' if safe else ''}{run_id}{suffix}"


def _version() -> str:
    try:
        return metadata.version("furnace-twin")
    except metadata.PackageNotFoundError:
        return "unknown"


@router.get("/{run_id}/export.csv", response_class=StreamingResponse, responses=NOT_FOUND)
def export_csv(run_id: str, manager: ManagerDep) -> StreamingResponse:
    """Every sample of the run as CSV (SI units in the column names; an empty cell is a missing reading)."""
    names, table = csv_columns(_arrays(manager, run_id))
    name = _filename(manager, run_id, ".csv")
    return StreamingResponse(_csv_rows(names, table), media_type="text/csv",
                             headers={"Content-Disposition": f'attachment; filename="{name}"'})


@router.get("/{run_id}/report.{fmt}", response_class=Response, responses={
    **NOT_FOUND, 200: {"content": {"application/pdf": {}, "image/png": {}}},
    422: {"description": "the format is neither pdf nor png"}})
async def report(run_id: str, fmt: Literal["pdf", "png"], manager: ManagerDep) -> Response:
    """A one-page report (``pdf`` or ``png``): scenario, charts with the metric windows, metrics in K and %,
    the last estimated field, the latest events (``twin.experiments.report``)."""
    z = _arrays(manager, run_id)
    row = manager.run(run_id)

    def render() -> bytes:
        metrics = row.metrics if row.metrics is not None else compute_metrics(z)
        state = manager.status(run_id) or row.status
        story = _story(manager, run_id)
        title = f"{row.label or story.auto_label} · run {run_id} · {state}"
        when = time.strftime("%Y-%m-%d %H:%M", time.localtime(row.started_at or row.created_at))
        what = (f"{'in force now' if state in ACTIVE_STATUSES else 'in force at the end'}: {story.text}",
                f"started {when} · furnace {manager.limits.furnace} · furnace-twin {_version()}")
        out = io.BytesIO()
        write_report(z, metrics, out, fmt=fmt, title=title, story=what)
        return out.getvalue()

    body = await run_in_threadpool(render)  # matplotlib: off the event loop
    return Response(body, media_type="application/pdf" if fmt == "pdf" else "image/png",
                    headers={"Content-Disposition": f'attachment; filename="{_filename(manager, run_id, "." + fmt)}"'})
