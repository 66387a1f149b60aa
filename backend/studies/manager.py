"""The server's design studies: validated on POST, queued, run one at a time on Dask in a background
thread (``twin.studies.engine.run_study``), and kept on disk under ``<data_dir>/studies/<id>/``.

Besides the engine's files (``cases/``, ``results.parquet``, ``results.csv``, ``figures/``, ``study.md``,
``summary.json``), a study folder holds ``request.json`` (the study as posted) and ``status.json`` (what
``GET /api/studies/{id}`` reports), rewritten at every finished case.  A study that was going when the
server stopped is ``interrupted`` after a restart; ``POST /api/studies/{id}/resume`` runs what is missing.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from backend.core.settings import Settings
from twin.config import FurnaceConfig
from twin.limits import scenario_limits
from twin.runs.folder import write_json
from twin.studies.cases import Case, expand, resolve_furnace
from twin.studies.engine import StudyProgress
from twin.studies.spec import StudyError, StudySpec

log = logging.getLogger(__name__)

#: files of a study folder that are served, with their media types (figures/*.png besides)
STUDY_FILES = {"results.parquet": "application/vnd.apache.parquet", "results.csv": "text/csv",
               "study.md": "text/markdown", "summary.json": "application/json"}
ACTIVE = ("queued", "running")
StudyRunner = Callable[..., dict[str, Any]]


class StudyNotFound(LookupError):
    pass


class StudyRejected(ValueError):
    """The study is invalid for this server (422); the message says what is wrong."""


class StudyConflict(RuntimeError):
    """The request does not fit the study's state (409)."""


@dataclass
class StudyState:
    id: str
    name: str | None
    furnace: str
    status: str  # queued, running, finished, stopped, interrupted, error
    created_at: float
    total: int
    finished: int = 0
    failed: int = 0
    skipped: int = 0
    workers: int = 0
    started_at: float | None = None
    ended_at: float | None = None
    error: str | None = None


def _default_runner(*args: Any, **kwargs: Any) -> dict[str, Any]:
    from twin.studies.engine import run_study

    return run_study(*args, **kwargs)


class StudyManager:
    def __init__(self, settings: Settings, cfg: FurnaceConfig, runner: StudyRunner | None = None, *,
                 furnace_name: str = "custom") -> None:
        self.settings, self.cfg, self.furnace_name = settings, cfg, furnace_name
        self.root = settings.studies_dir
        self.runner = runner or _default_runner
        self._lock = threading.Lock()
        self._states: dict[str, StudyState] = {}
        self._stops: dict[str, threading.Event] = {}
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._thread: threading.Thread | None = None
        self._closing = False
        self._load()

    # ---- folders ----
    def folder(self, study_id: str) -> Path:
        return self.root / study_id

    def _load(self) -> None:
        """Studies of earlier server processes; those that were going are now ``interrupted``."""
        if not self.root.is_dir():
            return
        for status_file in self.root.glob("*/status.json"):
            try:
                state = StudyState(**json.loads(status_file.read_text()))
            except (OSError, ValueError, TypeError) as exc:
                log.warning("skipping study folder %s: %s", status_file.parent, exc)
                continue
            if state.status in ACTIVE:
                state.status, state.error = "interrupted", "the server stopped while the study was going"
                write_json(status_file, asdict(state))
            self._states[state.id] = state

    def _persist(self, state: StudyState) -> None:
        write_json(self.folder(state.id) / "status.json", asdict(state))

    # ---- requests ----
    def validate(self, spec: StudySpec) -> tuple[str, FurnaceConfig, list[Case]]:
        """The study's furnace and cases, or :class:`StudyRejected` saying what is wrong."""
        s = self.settings
        try:
            if spec.n_cases > s.max_study_cases:
                raise StudyError(f"{spec.n_cases} cases: this server runs at most {s.max_study_cases} per study")
            name, cfg = resolve_furnace(spec, self.cfg, default_name=self.furnace_name, allow_paths=False)
            cases = expand(spec, cfg, scenario_limits(cfg, name))
        except StudyError as exc:
            raise StudyRejected(str(exc)) from None
        longest = max(cases, key=lambda c: c.scenario.duration)
        if longest.scenario.duration > s.max_duration_s:  # the scenario checks the twin's limit, not the server's
            raise StudyRejected(f"case {longest.index}: duration: {longest.scenario.duration:g} s exceeds this "
                                f"server's limit of {s.max_duration_s:g} s")
        return name, cfg, cases

    def plan(self, spec: StudySpec) -> dict[str, Any]:
        """Before a start: the study's cases (design points x seeds / samples) and its estimated wall time.

        The estimate scales the per-case wall time of this server's finished studies (their ``timing``:
        median case time per simulated second, and the first case's radiation-table load) to this study's
        simulated seconds on the workers it will get; None, with the reason, when no study has finished here."""
        from twin.studies.cluster import default_workers
        from twin.studies.report import design_fields

        _name, _cfg, cases = self.validate(spec)
        points = {json.dumps({p: c.params.get(p) for p in design_fields(spec)}, sort_keys=True) for c in cases}
        workers = self.settings.study_workers or default_workers()
        out: dict[str, Any] = {"cases": len(cases), "points": len(points), "per_point": len(cases) // len(points),
                               "workers": workers, "estimate_s": None, "basis": None}
        rate, load, basis = self._seconds_per_simulated_second()
        if rate is None:
            out["basis"] = "no study has finished on this server yet: no per-case time to go by"
            return out
        waves = -(-len(cases) // workers)
        mean_duration = sum(c.scenario.duration for c in cases) / len(cases)
        out["estimate_s"] = (load or 0.0) + waves * mean_duration * rate
        out["basis"] = basis
        return out

    def _seconds_per_simulated_second(self) -> tuple[float | None, float | None, str | None]:
        """Wall s per simulated s of a case, from the newest finished study of this server that has timings."""
        for state in self.all():
            if state.status != "finished":
                continue
            timing = (self.summary(state.id) or {}).get("timing") or {}
            if not timing.get("case_s"):
                continue
            try:
                _n, _c, old = self.validate(StudySpec.model_validate(self.request(state.id)))
            except (StudyRejected, OSError, ValueError):
                continue
            duration = sum(c.scenario.duration for c in old) / len(old)
            rate = float(timing["case_s"]) / duration
            return rate, timing.get("load_s"), (f"study {state.name or state.id}: {timing['case_s']:.1f} s per "
                                                f"{duration:g} s case (median), {timing.get('load_s') or 0:.0f} s "
                                                "first load")
        return None, None, None

    def submit(self, spec: StudySpec) -> StudyState:
        name, _cfg, cases = self.validate(spec)
        study_id = uuid.uuid4().hex[:12]
        folder = self.folder(study_id)
        folder.mkdir(parents=True, exist_ok=True)
        write_json(folder / "request.json", spec.document())
        state = StudyState(id=study_id, name=spec.name, furnace=name, status="queued", created_at=time.time(),
                           total=len(cases))
        with self._lock:
            self._states[study_id] = state
            self._persist(state)
        self._enqueue(study_id)
        log.info("study %s queued: %d cases", study_id, len(cases))
        return state

    def resume(self, study_id: str) -> StudyState:
        state = self.get(study_id)
        with self._lock:
            if state.status not in ("interrupted", "stopped", "error"):
                raise StudyConflict(f"study {study_id} is {state.status}: only an interrupted, stopped or failed "
                                    "study resumes")
            state.status, state.error, state.ended_at = "queued", None, None
            self._persist(state)
        self._enqueue(study_id)
        return state

    def stop(self, study_id: str) -> StudyState:
        state = self.get(study_id)
        with self._lock:
            if state.status not in ACTIVE:
                raise StudyConflict(f"study {study_id} is {state.status}, not going")
            self._stops.setdefault(study_id, threading.Event()).set()
            if state.status == "queued":
                state.status, state.ended_at = "stopped", time.time()
                self._persist(state)
        return state

    def get(self, study_id: str) -> StudyState:
        with self._lock:
            state = self._states.get(study_id)
        if state is None:
            raise StudyNotFound(f"no study with id {study_id!r}")
        return state

    def all(self) -> list[StudyState]:
        with self._lock:
            return sorted(self._states.values(), key=lambda s: s.created_at, reverse=True)

    def request(self, study_id: str) -> dict[str, Any]:
        result: dict[str, Any] = json.loads((self.folder(self.get(study_id).id) / "request.json").read_text())
        return result

    def summary(self, study_id: str) -> dict[str, Any] | None:
        path = self.folder(self.get(study_id).id) / "summary.json"
        try:
            result: dict[str, Any] = json.loads(path.read_text())
        except (OSError, ValueError):
            return None
        return result

    def figures(self, study_id: str) -> list[str]:
        """Names of the study's PNG figures, in the order the engine made them (metrics in product.md's order)."""
        names = {p.name for p in (self.folder(self.get(study_id).id) / "figures").glob("*.png")}
        made = [Path(f).name for f in (self.summary(study_id) or {}).get("figures", [])]
        return [n for n in made if n in names] + sorted(names - set(made))

    def file(self, study_id: str, name: str) -> Path:
        """A served file of the study: one of :data:`STUDY_FILES` or ``figures/<name>.png``."""
        folder = self.folder(self.get(study_id).id)
        if name in STUDY_FILES:
            path = folder / name
        elif name.startswith("figures/") and name.count("/") == 1 and name.endswith(".png") \
                and not name.split("/")[1].startswith("."):
            path = folder / name
        else:
            raise StudyNotFound(f"study {study_id} has no file {name!r}")
        if not path.is_file():
            raise StudyNotFound(f"study {study_id} has no {name} (yet)")
        return path

    # ---- the study thread ----
    def _enqueue(self, study_id: str) -> None:
        with self._lock:
            self._stops[study_id] = threading.Event()
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._serve, name="studies", daemon=True)
                self._thread.start()
        self._queue.put(study_id)

    def _serve(self) -> None:
        while True:
            study_id = self._queue.get()
            if study_id is None:
                return
            try:
                self._run(study_id)
            except Exception:  # never lose the thread: the next study must still run
                log.exception("study %s", study_id)

    def _run(self, study_id: str) -> None:
        state = self.get(study_id)
        stop = self._stops.setdefault(study_id, threading.Event())
        with self._lock:
            if state.status != "queued" or stop.is_set():
                return
            state.status, state.started_at = "running", time.time()
            self._persist(state)

        def progress(p: StudyProgress) -> None:
            with self._lock:
                state.total, state.finished, state.failed = p.total, p.finished, p.failed
                state.skipped, state.workers = p.skipped, p.workers
                self._persist(state)

        status, error = "finished", None
        try:
            spec = StudySpec.model_validate(self.request(study_id))
            name, cfg, cases = self.validate(spec)
            summary = self.runner(spec, cfg, self.folder(study_id), furnace_name=name, cases=cases,
                                  workers=self.settings.study_workers, scheduler=self.settings.study_scheduler,
                                  on_progress=progress, stop=stop)
            if summary.get("pending"):
                status = "interrupted" if self._closing or not stop.is_set() else "stopped"
            with self._lock:
                state.finished = len(summary["cases"]) - summary.get("pending", 0)
                state.failed, state.skipped = summary["failed"], summary["skipped"]
        except Exception as exc:
            log.exception("study %s failed", study_id)
            status, error = "error", f"{type(exc).__name__}: {exc}"
        with self._lock:
            state.status, state.error, state.ended_at = status, error, time.time()
            self._persist(state)

    def shutdown(self, timeout_s: float = 30.0) -> None:
        """Stop the running study (its finished cases stay; it is ``interrupted``, to resume) and end the thread."""
        with self._lock:
            self._closing = True
            for event in self._stops.values():
                event.set()
            thread = self._thread
        if thread is not None and thread.is_alive():
            self._queue.put(None)
            thread.join(timeout_s)
