"""The data directory's disk: how much it holds, how much is free, what a run may still write.

* **Quota** (``Settings.data_quota_mb``): a run is refused (507) when what the directory holds plus
  the run's estimated size (:func:`run_bytes`) would pass it, or when the disk would keep less than
  ``Settings.min_free_mb`` free; a running run that passes either stops with status ``error`` and
  that reason (its data kept).
* **Retention** (``Settings.retention_days``): ended runs older than that are deleted (their rows and
  folders), at start and before each new run.
* ``GET /api/health`` reports :meth:`DataDir.report`.

Example
-------
>>> from twin.config import small_config
>>> round(run_bytes(small_config(), 240.0) / 1e6, 1)   # MB of a default-length run of the small furnace
12.2
"""

from __future__ import annotations

import logging
import shutil
import threading
import time
from pathlib import Path
from typing import Any

from backend.storage.repository import ACTIVE_STATUSES, RunRepository
from twin.config import FurnaceConfig

log = logging.getLogger(__name__)

MB = 1e6
USAGE_CACHE_S = 5.0  # a walk of the data directory at most this often
#: bytes of a sample besides the two fields: t, eta, T_ref, T_mean_hat, t_field (5), tc, tc_hat (8),
#: u, u_ff (12) as float64, and the recording's ~40 scalar series (float64 value + time)
SAMPLE_BYTES = (5 + 8 + 12) * 8 + 40 * 16
RECORDING_IMAGES_PER_S = 2.0  # Settings.recording_image_interval_s = 0.5 s: two fields each


def run_bytes(cfg: FurnaceConfig, duration_s: float, image_interval_s: float = 0.5) -> float:
    """Estimated bytes a run leaves: its series (two float32 fields per sample) and its recording."""
    s = cfg.specimen
    cells = s.nx * s.ny
    samples = duration_s / cfg.sampling.t_s + 1
    images = duration_s / image_interval_s + 1
    return samples * (SAMPLE_BYTES + 2 * cells * 4) + images * 2 * cells * 4


def folder_bytes(path: Path) -> int:
    total = 0
    for p in path.rglob("*"):
        try:
            if p.is_file():
                total += p.stat().st_size
        except OSError:  # removed meanwhile
            pass
    return total


class DataDir:
    """Usage, free space and retention of one data directory (module docstring)."""

    def __init__(self, root: Path, quota_mb: float, min_free_mb: float, retention_days: float | None) -> None:
        self.root = Path(root)
        self.quota = quota_mb * MB
        self.min_free = min_free_mb * MB
        self.retention_days = retention_days
        self._lock = threading.Lock()
        self._used: tuple[float, int] | None = None  # (monotonic time, bytes)

    def used_bytes(self, fresh: bool = False) -> int:
        with self._lock:
            if fresh or self._used is None or time.monotonic() - self._used[0] > USAGE_CACHE_S:
                self._used = (time.monotonic(), folder_bytes(self.root) if self.root.exists() else 0)
            return self._used[1]

    def free_bytes(self) -> int:
        probe = self.root if self.root.exists() else self.root.parent
        return int(shutil.disk_usage(probe).free)

    def room_for(self, nbytes: float) -> str | None:
        """``None`` if ``nbytes`` more fit within the quota and the free-space reserve, else why not."""
        used, free = self.used_bytes(fresh=True), self.free_bytes()
        if used + nbytes > self.quota:
            return (f"the data directory holds {used / MB:.0f} MB of its {self.quota / MB:.0f} MB quota and this "
                    f"run needs about {nbytes / MB:.0f} MB: delete runs, shorten it, or raise "
                    f"FURNACE_TWIN_DATA_QUOTA_MB")
        if free - nbytes < self.min_free:
            return (f"the disk has {free / MB:.0f} MB free, this run needs about {nbytes / MB:.0f} MB and "
                    f"{self.min_free / MB:.0f} MB are kept free (FURNACE_TWIN_MIN_FREE_MB)")
        return None

    def over(self) -> str | None:
        """Why a running run must stop now (quota passed or the disk nearly full), else ``None``."""
        used, free = self.used_bytes(), self.free_bytes()
        if used > self.quota:
            return f"the data directory passed its {self.quota / MB:.0f} MB quota ({used / MB:.0f} MB)"
        if free < self.min_free:
            return f"the disk has only {free / MB:.0f} MB free (at least {self.min_free / MB:.0f} MB are kept free)"
        return None

    def apply_retention(self, repo: RunRepository, runs_dir: Path, now: float | None = None) -> list[str]:
        """Delete ended runs created more than ``retention_days`` ago; returns their ids."""
        if self.retention_days is None:
            return []
        cutoff = (time.time() if now is None else now) - self.retention_days * 86400.0
        gone = []
        for row in repo.runs_created_before(cutoff):
            if row.status in ACTIVE_STATUSES:
                continue
            shutil.rmtree(runs_dir / row.id, ignore_errors=True)
            repo.delete_run(row.id)
            gone.append(row.id)
        if gone:
            log.info("retention (%g days): deleted %d runs: %s", self.retention_days, len(gone), ", ".join(gone))
            self.used_bytes(fresh=True)
        return gone

    def report(self) -> dict[str, Any]:
        return {"used_mb": round(self.used_bytes() / MB, 1), "free_mb": round(self.free_bytes() / MB, 1),
                "quota_mb": round(self.quota / MB, 1), "min_free_mb": round(self.min_free / MB, 1),
                "retention_days": self.retention_days}
