"""A study's folder: one record per finished case (what a re-run resumes from), and the results table.

Layout of ``--out DIR``::

    study.json             the study document, the furnace and its digest
    cases/<key>.json       the record of each finished case (written atomically as it arrives)
    cases/<key>/           with --keep-series: metrics.json, scenario.json, timeseries.npz
    results.parquet        one row per case: index, key, status, the varied fields, every metric, timings
    results.csv            the same table as CSV
    figures/*.png, study.md, summary.json (the ``study --json`` object)

A case is "done" for a new invocation when its record says so (and, with --keep-series, its series
exist); failed cases are run again.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from twin.runs.folder import RunFolder, write_json
from twin.runs.metrics import METRIC_KEYS
from twin.studies.cases import Case

RESULTS_PARQUET = "results.parquet"
RESULTS_CSV = "results.csv"
#: per-case timing columns of the table (s), from the worker's record
TIMING_KEYS = ("setup_s", "plan_s", "run_s", "metrics_s")


class CaseStore:
    """The per-case records of one study folder."""

    def __init__(self, out: Path) -> None:
        self.out = Path(out)
        self.cases_dir = self.out / "cases"

    def record_path(self, key: str) -> Path:
        return self.cases_dir / f"{key}.json"

    def series_dir(self, key: str) -> Path:
        return self.cases_dir / key

    def load(self, key: str) -> dict[str, Any] | None:
        try:
            rec: dict[str, Any] = json.loads(self.record_path(key).read_text())
        except (OSError, ValueError):
            return None
        return rec if rec.get("key") == key else None

    def finished(self, keys: Iterable[str], *, keep_series: bool) -> dict[str, dict[str, Any]]:
        """Records of earlier invocations that count as done (status done, and series if asked)."""
        done = {}
        for key in keys:
            rec = self.load(key)
            if rec is None or rec.get("status") != "done":
                continue
            if keep_series and not (self.series_dir(key) / "timeseries.npz").is_file():
                continue
            done[key] = rec
        return done

    def save(self, rec: Mapping[str, Any], scenario_json: str) -> dict[str, Any]:
        """Store a worker's record (its series, if any, as files); returns the record as stored."""
        stored = {k: v for k, v in rec.items() if k != "series"}
        stored["scenario"] = json.loads(scenario_json)
        series = rec.get("series")
        if series is not None:
            run = RunFolder(self.series_dir(rec["key"]))
            run.write_timeseries_bytes(series)
            run.write_scenario(stored["scenario"])
            write_json(run.metrics, rec.get("metrics"))
            stored["out"] = str(run.folder)
        write_json(self.record_path(rec["key"]), stored)
        return stored


def _column(values: list[Any]) -> tuple[list[Any], Any]:
    """Values and an Arrow type for one column of varied-field values (lists and tables as JSON text)."""
    import pyarrow as pa

    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return values, pa.bool_()
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return values, pa.int64()
    if present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        return [None if v is None else float(v) for v in values], pa.float64()
    if present and all(isinstance(v, str) for v in present):
        return values, pa.string()
    return [None if v is None else json.dumps(v) for v in values], pa.string()


def results_table(cases: Sequence[Case], records: Mapping[str, Mapping[str, Any]], varied: Sequence[str]) -> Any:
    """The results as a ``pyarrow.Table``, one row per case in case order; unfinished cases are "pending"."""
    import pyarrow as pa

    rows = [records.get(c.key) or {} for c in cases]
    extra = sorted({k for r in rows for k, v in (r.get("metrics") or {}).items()
                    if k not in METRIC_KEYS and isinstance(v, (int, float))})
    cols: dict[str, Any] = {
        "index": pa.array([c.index for c in cases], pa.int64()),
        "key": pa.array([c.key for c in cases], pa.string()),
        "status": pa.array([r.get("status", "pending") for r in rows], pa.string()),
        "grid_point": pa.array([c.grid_point for c in cases], pa.int64()),
        "sample": pa.array([c.sample for c in cases], pa.int64()),
    }
    for path in varied:
        values, typ = _column([c.params.get(path) for c in cases])
        cols[path] = pa.array(values, typ)
    for key in (*METRIC_KEYS, *extra):
        cols[key] = pa.array([_float((r.get("metrics") or {}).get(key)) for r in rows], pa.float64())
    for key in TIMING_KEYS:
        cols[key] = pa.array([_float(r.get(key)) for r in rows], pa.float64())
    cols["warnings"] = pa.array([r.get("warnings") for r in rows], pa.int64())
    cols["worker"] = pa.array([r.get("worker") for r in rows], pa.string())
    cols["ending"] = pa.array([r.get("ending") for r in rows], pa.string())  # the run's, as RunSession.end says
    cols["ending_reason"] = pa.array([r.get("ending_reason") for r in rows], pa.string())
    cols["error"] = pa.array([r.get("error") for r in rows], pa.string())
    cols["scenario"] = pa.array([c.scenario.to_json() for c in cases], pa.string())
    return pa.table(cols)


def _float(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None


def write_results(out: Path, table: Any) -> tuple[Path, Path]:
    """results.parquet and results.csv (written beside each other, each atomically)."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    out.mkdir(parents=True, exist_ok=True)
    paths = out / RESULTS_PARQUET, out / RESULTS_CSV
    for path, write in ((paths[0], pq.write_table), (paths[1], pacsv.write_csv)):
        tmp = path.with_name(path.name + ".tmp")
        write(table, str(tmp))
        os.replace(tmp, path)
    return paths
