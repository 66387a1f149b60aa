"""Run a study on Dask: expand the cases, skip those an earlier invocation finished, run the rest on the
cluster, store each record as it arrives, then write the table, the figures and the report.

Data is never lost: every finished case is on disk before the next one is waited for, and the table,
figures and ``study.md`` are written also when the study is stopped, interrupted (Ctrl-C) or fails; a
re-run of the same study then computes only what is missing.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.config import FurnaceConfig
from twin.runs.folder import write_json
from twin.studies.cases import Case, expand
from twin.studies.cluster import study_client
from twin.studies.spec import StudySpec
from twin.studies.store import CaseStore, results_table, write_results
from twin.studies.timing import timing_figures
from twin.studies.worker import CaseTask, run_case

log = logging.getLogger(__name__)

#: how often the driver looks at a stop request while it waits for cases (s)
POLL_S = 0.25


@dataclass(frozen=True)
class StudyProgress:
    """Where a study stands: cases finished (done or failed, including skipped ones) of ``total``."""

    total: int
    finished: int
    failed: int
    skipped: int
    workers: int


ProgressFn = Callable[[StudyProgress], None]


def run_study(
    spec: StudySpec,
    cfg: FurnaceConfig,
    out: Path,
    *,
    furnace_name: str = "(running furnace)",
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    keep_series: bool = False,
    progress_bar: bool = False,
    on_progress: ProgressFn | None = None,
    stop: threading.Event | None = None,
    cases: list[Case] | None = None,
) -> dict[str, Any]:
    """Run ``spec`` on ``cfg`` into the folder ``out``; returns the ``study --json`` object of product.md.

    The cluster is ``client`` if given, else an existing ``scheduler``, else a LocalCluster of ``workers``
    processes (default: one per core).  ``stop`` ends the study early (cases not finished stay pending).
    """
    from twin.studies.figures import plot_study
    from twin.studies.report import write_report

    cases = cases if cases is not None else expand(spec, cfg)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    digest = cfg.digest()
    write_json(out / "study.json", {"study": spec.document(), "furnace": furnace_name, "furnace_digest": digest,
                                    "cases": len(cases)})
    store = CaseStore(out)
    keys = list(dict.fromkeys(c.key for c in cases))  # unique, in case order (equal scenarios run once)
    earlier = store.finished(keys, keep_series=keep_series)
    records: dict[str, dict[str, Any]] = dict(earlier)
    todo = [k for k in keys if k not in earlier]
    scenario_json = {c.key: c.scenario.to_json() for c in cases}
    fresh: list[dict[str, Any]] = []
    n_workers = 0
    log.info("study %s: %d cases, %d found done in %s, %d to run", spec.name or out.name, len(cases),
             len(earlier), out, len(todo))
    t0 = time.perf_counter()
    try:
        if todo and not (stop is not None and stop.is_set()):
            with _cluster(client, workers, scheduler) as (cl, n_workers):
                progress = _Progress(len(keys), len(earlier), n_workers, progress_bar, on_progress)
                try:
                    for rec in _execute(cl, todo, digest, cfg, scenario_json, keep_series, stop):
                        stored = store.save(rec, scenario_json[rec["key"]])
                        records[rec["key"]] = stored
                        fresh.append(stored)
                        progress.update(stored["status"] == "failed")
                finally:
                    progress.close()
    finally:
        wall_s = time.perf_counter() - t0
        summary = _summary(cases, records, earlier, n_workers, wall_s, out, keep_series)
        summary["timing"] = timing_figures([records[k] for k in keys if k in records], wall_s, n_workers, fresh)
        summary["invocations"] = log_invocation(out, summary)
        table = results_table(cases, records, spec.varied())
        summary["results"] = str(write_results(out, table)[0])
        try:
            summary["figures"] = [str(p) for p in plot_study(spec, cases, table, out / "figures")]
        except Exception:  # a figure problem must not lose the results
            log.exception("study figures failed")
            summary["figures"] = []
        write_report(out / "study.md", spec, furnace_name, summary)
        write_json(out / "summary.json", summary)
    return summary


def log_invocation(out: Path, summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Append this invocation to ``invocations.jsonl`` (a resumed study keeps the story of its runs); all of them."""
    import json

    entry = {"at": time.time(), "workers": summary["workers"], "computed": summary["computed"],
             "skipped": summary["skipped"], "failed": summary["failed"], "pending": summary["pending"],
             "wall_s": summary["wall_s"]}
    path = out / "invocations.jsonl"
    with open(path, "a") as fh:
        fh.write(json.dumps(entry) + "\n")
    entries = []
    for line in path.read_text().splitlines():
        try:
            entries.append(json.loads(line))
        except ValueError:  # a line cut by a crash
            continue
    return entries


@contextmanager
def _cluster(client: Any, workers: int | None, scheduler: str | None) -> Iterator[tuple[Any, int]]:
    if client is not None:
        yield client, len(client.scheduler_info(n_workers=-1)["workers"])
        return
    with study_client(workers=workers, scheduler=scheduler) as pair:
        yield pair


def _execute(
    client: Any, todo: list[str], digest: str, cfg: FurnaceConfig, scenario_json: dict[str, str],
    keep_series: bool, stop: threading.Event | None,
) -> Iterator[dict[str, Any]]:
    """Submit every case and yield each worker record as it arrives (failures of Dask itself included)."""
    from distributed import wait

    furnace = client.scatter(cfg.model_dump(mode="json"), broadcast=True, hash=False)
    tag = uuid.uuid4().hex[:8]
    futures = {
        client.submit(run_case, CaseTask(k, digest, scenario_json[k], keep_series), furnace,
                      key=f"furnace-twin-case-{k}-{tag}", pure=False): k
        for k in todo
    }
    pending = set(futures)
    try:
        while pending:
            if stop is not None and stop.is_set():
                log.info("study stopped: %d cases not run", len(pending))
                return
            try:
                done, pending = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED")
            except TimeoutError:
                continue
            for fut in done:
                key = futures.pop(fut)
                try:
                    rec = fut.result()
                except Exception as exc:  # the worker died (KilledWorker) or the task was lost
                    rec = {"key": key, "status": "failed", "metrics": None, "worker": None,
                           "error": f"{type(exc).__name__}: {exc}"}
                fut.release()
                yield rec
    finally:
        if pending:
            client.cancel(list(pending))


class _Progress:
    """A tqdm bar on stderr (CLI) and/or a callback (the server's study status)."""

    def __init__(self, total: int, skipped: int, workers: int, bar: bool, callback: ProgressFn | None) -> None:
        self.total, self.skipped, self.workers = total, skipped, workers
        self.finished, self.failed = skipped, 0
        self.callback = callback
        self.bar = None
        if bar:
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=skipped, desc=f"study ({workers} workers)", unit="case",
                            file=sys.stderr)
        self._emit()

    def _emit(self) -> None:
        if self.callback is not None:
            self.callback(StudyProgress(self.total, self.finished, self.failed, self.skipped, self.workers))

    def update(self, failed: bool) -> None:
        self.finished += 1
        self.failed += int(failed)
        if self.bar is not None:
            self.bar.update(1)
            if self.failed:
                self.bar.set_postfix(failed=self.failed)
        self._emit()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _summary(
    cases: list[Case], records: dict[str, dict[str, Any]], earlier: dict[str, Any], workers: int, wall_s: float,
    out: Path, keep_series: bool,
) -> dict[str, Any]:
    rows = []
    for c in cases:
        rec = records.get(c.key)
        status = "pending" if rec is None else "skipped" if c.key in earlier else rec["status"]
        rec = rec or {}
        row: dict[str, Any] = {"key": c.key, "index": c.index, "params": c.params, "status": status,
                               "metrics": rec.get("metrics"), "error": rec.get("error")}
        if keep_series and rec.get("out"):
            row["out"] = rec["out"]
        rows.append(row)
    count = {s: sum(r["status"] == s for r in rows) for s in ("done", "failed", "skipped", "pending")}
    return {"cases": rows, "computed": count["done"] + count["failed"], "skipped": count["skipped"],
            "failed": count["failed"], "pending": count["pending"], "workers": workers, "wall_s": wall_s,
            "out": str(out)}
