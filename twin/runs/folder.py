"""A run's folder: the one place that knows its files' names and writes them.

Layout (product.md)::

    scenario.json     the scenario as run
    timeseries.npz    the run record (``twin.runs.record``); while the run goes, ``timeseries.parts/``
                      (``twin.runs.series_store``) until it is consolidated
    metrics.json      the metrics with ``status`` and ``status_reason`` (how the run ended)
    faults.json       the faults injected and what the twin detected, ``{"injected": [...], "events": [...]}``
    recording.rrd     the rerun recording (written by a sink of the server or the CLI)
    figures           PNG figures of a headless run

The CLI (``twin.experiments.run``), the server (``backend.runs``) and the study store (``--keep-series``)
write a run's folder through :class:`RunFolder`.  Every file is replaced atomically (a temporary file in the
same folder, then ``os.replace``): a reader or a crash never sees half a file, and after a crash the folder
holds the last complete flush.  JSON goes through :func:`twin.jsonable.jsonable` (NaN -> null).

>>> import tempfile
>>> run = RunFolder(Path(tempfile.mkdtemp()) / "run-1")
>>> run.write_metrics({"mean_error_steady_max": float("nan")}, status="finished", reason=None)
>>> run.metrics.read_text().split()
['{', '"mean_error_steady_max":', 'null,', '"status":', '"finished",', '"status_reason":', 'null', '}']
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.jsonable import jsonable
from twin.runs.record import save_arrays

RECORDING = "recording.rrd"
TIMESERIES = "timeseries.npz"
METRICS = "metrics.json"
SCENARIO = "scenario.json"
FAULTS = "faults.json"


def write_atomic(path: Path, data: bytes) -> None:
    """Write via a temporary file beside ``path`` and rename: a reader or a crash never sees half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: Path, obj: Any) -> None:
    """``obj`` as indented JSON (NaN / inf as null), atomically."""
    write_atomic(path, json.dumps(jsonable(obj), indent=2, allow_nan=False).encode())


@dataclass(frozen=True)
class RunFolder:
    """The paths of one run's files (only these are ever served for the run) and their writers."""

    folder: Path

    @property
    def recording(self) -> Path:
        return self.folder / RECORDING

    @property
    def timeseries(self) -> Path:
        return self.folder / TIMESERIES

    @property
    def metrics(self) -> Path:
        return self.folder / METRICS

    @property
    def scenario(self) -> Path:
        return self.folder / SCENARIO

    @property
    def faults(self) -> Path:
        return self.folder / FAULTS

    def create(self) -> RunFolder:
        self.folder.mkdir(parents=True, exist_ok=True)
        return self

    def write_scenario(self, scenario: Any) -> None:
        """``scenario.json``: a ``twin.scenario.Scenario`` (or its JSON dict)."""
        write_json(self.scenario, scenario.model_dump(mode="json") if hasattr(scenario, "model_dump") else scenario)

    def write_metrics(self, metrics: Mapping[str, Any], *, status: str | None = None,
                      reason: str | None = None) -> None:
        """``metrics.json``; with ``status``, how the run ended (``status``, ``status_reason``) as well."""
        doc = dict(metrics)
        if status is not None:
            doc.update(status=status, status_reason=reason)
        write_json(self.metrics, doc)

    def write_faults(self, injected: Sequence[Any], events: Sequence[Mapping[str, Any]]) -> None:
        """``faults.json``: the faults injected (``twin.scenario.FaultSpec``) and the fault events so far."""
        write_json(self.faults, {"injected": [f.model_dump(mode="json") for f in injected], "events": list(events)})

    def write_timeseries(self, arrays: Mapping[str, Any], *, compress: bool = True) -> None:
        """``timeseries.npz`` at once (``compress=False`` for a file rewritten at every flush)."""
        save_arrays(self.timeseries, arrays, compress=compress)

    def write_timeseries_bytes(self, npz: bytes) -> None:
        """``timeseries.npz`` as made elsewhere (a study worker's bytes)."""
        write_atomic(self.timeseries, npz)

    def remove(self) -> None:
        """Delete the folder: first out of sight (renamed to ``.deleted-<id>``, atomic), then its files."""
        trash = self.folder.with_name(f".deleted-{self.folder.name}")
        if self.folder.is_dir():
            self.folder.rename(trash)
        shutil.rmtree(trash, ignore_errors=True)
