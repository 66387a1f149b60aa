"""One run as one object: :class:`RunSession`, hosted alike by the CLI, the study workers and the server.

A session holds a run's loop (``twin.runs.interface.Loop``: in this process or in a child process), its
folder (``twin.runs.folder.RunFolder``: where the scenario, the series, the metrics go), the sinks that
consume its snapshots (a rerun recording, ...) and the run's ending.  Its hosts differ only in how they pace
it and what else they keep:

* ``furnace-twin run`` and the campaign (``twin.experiments.run.execute_run``): :meth:`RunSession.run` to
  the end, as fast as the loop goes;
* a study worker (``twin.studies.worker``): :meth:`RunSession.run` without a folder (the record travels back);
* the server (``backend.runs.worker.RunWorker``): :meth:`step` at the scenario's speed between live changes
  (``twin.runs.changes.ChangeQueue``), :meth:`flush` every few seconds, :meth:`end`, :meth:`metrics` and
  :meth:`close` when the run stops.

While the run goes the series is appended in parts (``twin.runs.series_store``) at each :meth:`flush`, so a
crash loses at most the samples since; :meth:`close` writes ``timeseries.npz``.

The workflow, on the small furnace (a few samples of the default scenario)::

    >>> import tempfile
    >>> from pathlib import Path
    >>> from twin.config import small_config
    >>> from twin.runs.loop import ClosedLoop
    >>> from twin.scenario import Scenario
    >>> cfg = small_config()
    >>> run = RunSession(ClosedLoop(cfg, Scenario(duration=0.5)), RunFolder(Path(tempfile.mkdtemp())))
    >>> result = run.run()
    >>> result["status"], len(run.loop.timeseries()["t"])
    ('finished', 6)
    >>> sorted(p.name for p in run.folder.folder.iterdir())
    ['metrics.json', 'scenario.json', 'timeseries.npz']
"""

from __future__ import annotations

import logging
import shutil
from collections.abc import Sequence
from typing import Any, Protocol

from twin.furnace.interface import FurnaceLost
from twin.jsonable import jsonable
from twin.runs.folder import RunFolder
from twin.runs.interface import Loop
from twin.runs.outage import run_ending
from twin.runs.series_store import consolidate, parts_dir

log = logging.getLogger(__name__)


class SnapshotSink(Protocol):
    """Consumes snapshots of one run (a rerun recording, a viser scene, ...)."""

    def add(self, snap: Any) -> None: ...

    def flush(self) -> None: ...

    def close(self) -> None: ...


class RunSession:
    """A run's loop, folder, sinks and ending (module docstring)."""

    def __init__(self, loop: Loop, folder: RunFolder | None = None, *, sinks: Sequence[SnapshotSink] = ()) -> None:
        self.loop = loop
        self.folder = folder
        self.sinks = list(sinks)
        self.latest: Any = None  #: the last snapshot (``None`` before the first sample)
        self.ending: tuple[str, str | None] | None = None  #: (status, status_reason) once :meth:`end` was called
        self._closed = False
        if folder is not None:
            folder.create().write_scenario(loop.scenario)

    @property
    def t(self) -> float:
        """Run time of the last sample (s); 0 before the first."""
        return float(self.latest.t) if self.latest is not None else 0.0

    def step(self) -> Any:
        """One sample of the loop, handed to the sinks."""
        snap = self.loop.step()
        self.latest = snap
        for sink in self.sinks:
            sink.add(snap)
        return snap

    def flush(self) -> None:
        """Append the new samples to the folder's series parts and flush the sinks."""
        if self.folder is not None and self.latest is not None:
            self.loop.append_series(self.folder.folder)
        for sink in self.sinks:
            sink.flush()

    def end(self, end: str, error: str | None = None) -> tuple[str, str | None]:
        """The run's status and reason for the host's ``end`` (finished, stopped, error, plant_lost): the loop's
        verdict (a run blind at its end ended ``degraded``, ``twin.runs.outage.run_ending``)."""
        got: tuple[str, str | None] | None = None
        if self.latest is not None:
            try:
                status, reason = self.loop.ending(end, error)
                got = (str(status), reason)
            except Exception:
                log.exception("the run's ending failed")
        self.ending = got if got is not None else run_ending(end, error, None, self.t)
        return self.ending

    def metrics(self) -> dict[str, Any] | None:
        """The metrics so far as JSON values (NaN -> null) with the ending once known; ``None`` before the first
        sample or if they fail."""
        if self.latest is None:
            return None
        try:
            metrics: dict[str, Any] = jsonable(dict(self.loop.metrics()))
        except Exception:
            log.exception("the run's metrics failed")
            return None
        if self.ending is not None:
            metrics.update(status=self.ending[0], status_reason=self.ending[1])
        return metrics

    def close(self, *, compress: bool = False) -> None:
        """The last flush, ``timeseries.npz`` from the parts (``compress``: rewritten compressed from the loop's
        record instead, for a file that is kept), the sinks and the loop closed; idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.folder is not None:
                if compress and self.latest is not None:
                    self.folder.write_timeseries(self.loop.timeseries())
                    shutil.rmtree(parts_dir(self.folder.folder), ignore_errors=True)
                else:
                    self.flush()
                    consolidate(self.folder.folder, self.folder.timeseries, load=False)
        finally:
            for sink in self.sinks:
                sink.close()
            self.loop.close()

    def run(self, *, flush_every_s: float = 10.0) -> dict[str, Any]:
        """Step to the end, flushing every ``flush_every_s`` run seconds; write ``metrics.json`` (with status) and
        return the metrics with ``status``, ``status_reason`` (and ``error`` for a lost furnace: the data up to
        it is written all the same).  A run that fails (the estimate diverged, ...) or is interrupted (Ctrl-C)
        writes its data and ``metrics.json`` with status ``error`` / ``stopped``, then raises."""
        flush_every = max(1, int(round(flush_every_s / self.loop.t_s)))
        end, error = "finished", None
        failure: BaseException | None = None
        try:
            while not self.loop.done:
                snap = self.step()
                if snap.j % flush_every == 0 and snap.j > 0:
                    self.flush()
        except FurnaceLost as exc:
            log.error("the furnace was lost: %s", exc)
            end, error = "plant_lost", str(exc)
        except KeyboardInterrupt as exc:
            end, failure = "stopped", exc
        except Exception as exc:
            end, error, failure = "error", f"{type(exc).__name__}: {exc}", exc
        finally:
            self.close(compress=True)
        status, reason = self.end(end, error)
        metrics = {**self.loop.metrics(), "status": status, "status_reason": reason}
        if self.folder is not None:
            self.folder.write_metrics(metrics)
        if failure is not None:
            raise failure
        result: dict[str, Any] = dict(metrics)
        if error is not None:
            result["error"] = error
        return result
