"""What a Dask worker runs: one case of a study, as one closed-loop run.

:func:`run_case` never raises: an error in a case (an unreachable reference, a solver failure, a bug)
comes back as a record with ``status = "failed"`` and the error, so one case never stops a study.

The furnace configuration and its radiation tables are loaded once per worker process and kept in a
module-level cache keyed by the configuration digest (:func:`furnace_of`): every later case of the same
furnace on that worker reuses them.  A record says whether its case paid for the load
(``radiation_loaded``) and how long the set-up took, which is how the tests and the study report check
that tables are not loaded per case.
"""

from __future__ import annotations

import io
import logging
import os
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.config import FurnaceConfig, config_from_dict
from twin.jsonable import jsonable

log = logging.getLogger(__name__)

_LOCK = threading.Lock()
_FURNACES: dict[str, tuple[FurnaceConfig, Any, Any]] = {}  # digest -> config, radiation model, limits
_TRUTHS: dict[str, Any] = {}  # digest -> the simulated furnace's own radiation model (issue 10's truth)


@dataclass(frozen=True)
class CaseTask:
    """What travels to the worker with each case: small and plain (the furnace travels once, scattered)."""

    key: str
    furnace_digest: str
    scenario_json: str
    keep_series: bool = False


def furnace_of(digest: str, furnace: dict[str, Any]) -> tuple[FurnaceConfig, Any, Any, bool]:
    """(config, radiation model, scenario limits, loaded now?) of a furnace, cached in this process by its
    digest."""
    with _LOCK:
        hit = _FURNACES.get(digest)
        if hit is not None:
            return (*hit, False)
        from twin.limits import scenario_limits
        from twin.radiation import radiation_model

        cfg = config_from_dict(furnace)
        if cfg.digest() != digest:
            raise ValueError(f"furnace digest mismatch: the client sent {digest}, the worker computes "
                             f"{cfg.digest()} (different furnace-twin versions on client and worker?)")
        entry = (cfg, radiation_model(cfg), scenario_limits(cfg))
        _FURNACES[digest] = entry
        log.info("worker %s: furnace %s loaded", os.getpid(), digest)
        return (*entry, True)


def truth_of(digest: str, cfg: FurnaceConfig) -> Any:
    """The simulated furnace's own radiation model (``twin.furnace.simulated.truth``), loaded once per
    worker process like the model's table (a case with ``truth = "shared"`` never asks for it)."""
    with _LOCK:
        if digest not in _TRUTHS:
            from twin.furnace.simulated.truth import truth_radiation

            _TRUTHS[digest] = truth_radiation(cfg)
        return _TRUTHS[digest]


#: warnings of a case kept in its record (the rest are counted)
KEEP_WARNINGS = 5


class CaseWarnings(logging.Handler):
    """Collects the ``twin`` warnings of the case running in this thread (EKF gating, re-plans, ...)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.thread = threading.get_ident()
        self.count = 0
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread != self.thread:
            return
        self.count += 1
        if len(self.messages) < KEEP_WARNINGS:
            self.messages.append(f"{record.name}: {record.getMessage()}")


@contextmanager
def case_warnings() -> Iterator[CaseWarnings]:
    handler = CaseWarnings()
    logger = logging.getLogger("twin")
    logger.addHandler(handler)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def run_case(task: CaseTask, furnace: dict[str, Any]) -> dict[str, Any]:
    """Run one case on the furnace (its configuration as a dict) to its end.

    Returns the record of product.md's ``study --json`` case plus timings (s).

    Record keys: ``key``, ``status`` ("done" | "failed"), ``metrics`` (None if failed; with the run's ``status``
    and ``status_reason`` as the CLI's ``metrics.json``), ``error``, ``ending`` and ``ending_reason`` (the run's
    ending as :meth:`twin.runs.session.RunSession.end` says it: finished, degraded, error, plant_lost; None when the
    case failed before its loop was built),
    ``worker``, ``started``/``finished`` (unix s), ``setup_s`` (configuration and radiation tables),
    ``radiation_loaded``, ``plan_s`` (building the loop: model, feedforward OCP, gains), ``run_s``
    (the samples), ``metrics_s``, ``warnings`` (how many the case logged) with the first few
    ``warning_messages``, and ``series`` (``timeseries.npz`` bytes) with ``keep_series``.
    """
    rec: dict[str, Any] = {"key": task.key, "status": "failed", "metrics": None, "error": None,
                           "ending": None, "ending_reason": None,
                           "worker": worker_name(), "started": time.time(), "setup_s": None,
                           "radiation_loaded": False, "plan_s": None, "run_s": None, "metrics_s": None,
                           "series": None}
    t0 = time.perf_counter()
    with case_warnings() as warned:
        _run(task, furnace, rec, t0)
    rec["warnings"], rec["warning_messages"] = warned.count, warned.messages
    rec["finished"] = time.time()
    return rec


def _run(task: CaseTask, furnace: dict[str, Any], rec: dict[str, Any], t0: float) -> None:
    from twin.furnace.simulated import SimulatedFurnace
    from twin.runs.loop import ClosedLoop
    from twin.runs.session import RunSession
    from twin.scenario import Scenario

    try:
        cfg, rad, limits, loaded = furnace_of(task.furnace_digest, furnace)
        rec["radiation_loaded"] = loaded
        scenario = Scenario.model_validate_json(task.scenario_json, context={"limits": limits})
        own = truth_of(task.furnace_digest, cfg) if scenario.truth == "independent" else None
        t1 = time.perf_counter()
        rec["setup_s"] = t1 - t0
        loop = ClosedLoop(cfg, scenario, rad, furnace=SimulatedFurnace.for_scenario(cfg, scenario, rad,
                                                                                      truth_radiation=own))
        t2 = time.perf_counter()
        rec["plan_s"] = t2 - t1
        session = RunSession(loop)  # no folder: the record travels back to the client, which writes it
        try:
            result = session.run()  # to the end; the ending is known even when it raises
        finally:
            if session.ending is not None:
                rec["ending"], rec["ending_reason"] = session.ending
        t3 = time.perf_counter()
        rec["run_s"] = t3 - t2
        if "error" in result:  # the furnace was lost (logged by the session): the case did not finish
            rec["error"] = result["error"]
            return
        rec["metrics"] = jsonable(result)
        if task.keep_series:  # the timeseries.npz layout (product.md); the client writes the file
            buf = io.BytesIO()
            np.savez_compressed(buf, **{k: np.asarray(v) for k, v in loop.timeseries().items()})  # type: ignore[arg-type]
            rec["series"] = buf.getvalue()
        rec["metrics_s"] = time.perf_counter() - t3
        rec["status"] = "done"
    except Exception as exc:  # a failed case is a result, never an error of the study
        log.exception("case %s failed", task.key)
        rec["error"] = f"{type(exc).__name__}: {exc}"

