"""After a restart: runs that were going when the server died are marked ``interrupted``, and
their metrics are recomputed from the last flushed ``timeseries.npz`` (``twin.runs.metrics``), so
their data up to the crash stays readable and comparable."""

from __future__ import annotations

import logging
from pathlib import Path

from backend.frames import json_safe
from backend.repository import RunRepository
from backend.run_files import RunFiles, write_json_atomic
from twin.runs.metrics import compute_metrics
from twin.runs.record import load_arrays

log = logging.getLogger(__name__)


def recover_interrupted(repo: RunRepository, runs_dir: Path) -> list[str]:
    """Mark crashed runs interrupted; store metrics of the data they left. Returns their ids."""
    ids = repo.mark_interrupted()
    for run_id in ids:
        files = RunFiles(runs_dir / run_id)
        if not files.timeseries.is_file():
            continue
        try:
            metrics = json_safe(compute_metrics(load_arrays(files.timeseries)))
        except Exception as exc:  # a file from an older layout: keep the run, say why
            log.warning("run %s: no metrics from %s: %s", run_id, files.timeseries, exc)
            continue
        write_json_atomic(files.metrics, metrics)
        repo.save_progress(run_id, None, metrics)
    if ids:
        log.warning("runs interrupted by the last shutdown: %s", ", ".join(ids))
    return ids
