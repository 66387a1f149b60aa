"""Thermocouple placement on the server (issue 25, the paper's Remark 3): ``furnace-twin place-tcs`` for the
Studies view.

One ranking per specimen mode (fixed, oscillating) of the loaded furnace, made once per server in a worker
thread when first asked for (:func:`twin.experiments.place_tcs.rank_positions`: the twin's plan, the reduced
model's Gramians, the greedy choice; 5-30 s) and kept in memory; a failed one is made again when asked again.
Greedy's first k choices are the same whatever the count asked for, so one ranking of ``RANKED`` positions
serves every count from 1 to ``RANKED`` (the ``--count`` of the command).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from twin.config import FurnaceConfig

log = logging.getLogger(__name__)

#: positions ranked per mode (the command's largest --count)
RANKED = 6

Rank = Callable[..., dict[str, Any]]


@dataclass
class PlacementJob:
    """One specimen mode's ranking: being made, made (``result``) or failed (``error``)."""

    oscillate: bool
    state: Literal["computing", "done", "failed"] = "computing"
    seconds: float | None = None
    result: dict[str, Any] | None = None
    error: str | None = None


class PlacementService:
    """The rankings of one server's furnace (module docstring).

    ``radiation_of(cfg)`` gives the twin's radiation model (it waits while the tables load); ``rank`` is
    :func:`twin.experiments.place_tcs.rank_positions` (a test may pass a cheaper one).
    """

    def __init__(self, cfg: FurnaceConfig, radiation_of: Callable[[FurnaceConfig], Any] | None,
                 rank: Rank | None = None) -> None:
        self.cfg = cfg
        self._radiation_of = radiation_of
        self._rank = rank
        self._jobs: dict[bool, PlacementJob] = {}
        self._lock = threading.Lock()

    def get(self, oscillate: bool) -> PlacementJob | None:
        with self._lock:
            return self._jobs.get(bool(oscillate))

    def start(self, oscillate: bool) -> PlacementJob:
        """The mode's job: the one made or being made, else a new one started in a worker thread."""
        key = bool(oscillate)
        with self._lock:
            job = self._jobs.get(key)
            if job is not None and job.state != "failed":
                return job
            job = self._jobs[key] = PlacementJob(key)
        threading.Thread(target=self._work, args=(job,), name=f"place-tcs-{'osc' if key else 'fixed'}",
                         daemon=True).start()
        return job

    def _work(self, job: PlacementJob) -> None:
        t0 = time.monotonic()
        try:
            if self._radiation_of is None:
                raise RuntimeError("this server's loop has no radiation model to rank positions with")
            rank = self._rank
            if rank is None:
                from twin.experiments.place_tcs import rank_positions

                rank = rank_positions
            result = rank(self.cfg, count=RANKED, oscillate=job.oscillate, radiation=self._radiation_of(self.cfg))
        except Exception as exc:  # noqa: BLE001  (reported to the client as the job's error, and logged)
            log.exception("TC placement (%s) failed", "oscillating" if job.oscillate else "fixed")
            with self._lock:
                job.state, job.error, job.seconds = "failed", f"{type(exc).__name__}: {exc}", time.monotonic() - t0
            return
        with self._lock:
            job.state, job.result, job.seconds = "done", result, time.monotonic() - t0
        log.info("TC placement (%s) ranked in %.1f s", "oscillating" if job.oscillate else "fixed", job.seconds)
