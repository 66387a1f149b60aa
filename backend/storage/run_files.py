"""A run's folder: ``scenario.json``, ``timeseries.npz``, ``metrics.json``, ``recording.rrd``, ``faults.json``
(the faults injected into the run and what the twin detected, as ``[{"t", "text"}]``).

Files are replaced atomically (write to a temporary name, then ``os.replace``), so a
reader or a crash never sees half a file: after a crash the folder holds the last
complete flush.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Mapping
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


@dataclass(frozen=True)
class RunFiles:
    """Paths of one run's files (only these are ever served for the run)."""

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

    def remove(self) -> None:
        """Delete the folder: first out of sight (renamed to ``.deleted-<id>``, atomic), then its files."""
        trash = self.folder.with_name(f".deleted-{self.folder.name}")
        if self.folder.is_dir():
            self.folder.rename(trash)
        shutil.rmtree(trash, ignore_errors=True)


def write_json_atomic(path: Path, obj: Any) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(jsonable(obj), indent=2, sort_keys=True, allow_nan=False))
    os.replace(tmp, path)


def write_npz_atomic(path: Path, arrays: Mapping[str, Any]) -> None:
    """The run's time series, atomically and uncompressed (it is rewritten every few seconds)."""
    save_arrays(path, arrays, compress=False)
