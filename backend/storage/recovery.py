"""After a restart: runs that were going when the server died are marked ``interrupted`` with an end
time (when their folder was last written), their flushed time series consolidated into
``timeseries.npz`` and their metrics recomputed from it (``twin.runs.metrics``), and their recording
given the footer the crash left out (``backend.storage.recording_repair``), so their data up to the crash
stays readable and comparable."""

from __future__ import annotations

import logging
from pathlib import Path

from backend.storage.recording_repair import repair_recording
from backend.storage.repository import RunRepository
from twin.jsonable import jsonable
from twin.runs.folder import RunFolder
from twin.runs.metrics import run_metrics
from twin.runs.record import load_arrays
from twin.runs.series_store import consolidate, has_parts

log = logging.getLogger(__name__)
INTERRUPTED_REASON = "the server stopped while the run was going"  # as the run record says (mark_interrupted)


def recover_interrupted(repo: RunRepository, runs_dir: Path) -> list[str]:
    """Mark crashed runs interrupted; store metrics of the data they left. Returns their ids."""
    ids = repo.mark_interrupted()
    for run_id in ids:
        files = RunFolder(runs_dir / run_id)
        last_write = max((p.stat().st_mtime for p in files.folder.rglob("*") if p.is_file()), default=None) \
            if files.folder.is_dir() else None
        if last_write is not None:
            repo.set_ended_at(run_id, last_write)
        if files.recording.is_file() and not repair_recording(files.recording):
            log.warning("run %s: its recording could not be repaired", run_id)
        if has_parts(files.folder):  # what was flushed before the crash, as one timeseries.npz
            try:
                consolidate(files.folder, files.timeseries, load=False)
            except Exception as exc:
                log.warning("run %s: cannot consolidate its time series: %s", run_id, exc)
        if not files.timeseries.is_file():
            continue
        try:
            metrics = jsonable({**run_metrics(load_arrays(files.timeseries)), "status": "interrupted",
                                "status_reason": INTERRUPTED_REASON})
        except Exception as exc:  # a file from an older layout: keep the run, say why
            log.warning("run %s: no metrics from %s: %s", run_id, files.timeseries, exc)
            continue
        files.write_metrics(metrics)
        repo.save_progress(run_id, None, metrics)
    if ids:
        log.warning("runs interrupted by the last shutdown: %s", ", ".join(ids))
    return ids
