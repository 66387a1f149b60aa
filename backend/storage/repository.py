"""Run persistence: one SQLite file (WAL) with the runs and the changes made while they ran.

The table ``runs`` holds the scenario, status, timestamps (unix s), the latest values and
the metrics of every run; ``changes`` holds each reference / oscillation change with the
simulated time at which it was applied.  All methods are thread-safe (one connection,
one lock), so the run workers write from their own threads.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

_SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    id TEXT PRIMARY KEY,
    scenario TEXT NOT NULL,
    status TEXT NOT NULL,
    created_at REAL NOT NULL,
    started_at REAL,
    ended_at REAL,
    latest TEXT,
    metrics TEXT,
    error TEXT
);
CREATE TABLE IF NOT EXISTS changes (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    run_id TEXT NOT NULL REFERENCES runs(id),
    kind TEXT NOT NULL,
    body TEXT NOT NULL,
    requested_at REAL NOT NULL,
    status TEXT NOT NULL,
    applied_t REAL,
    message TEXT
);
CREATE INDEX IF NOT EXISTS changes_run ON changes(run_id);
"""
#: columns added after the first release: (name, SQL type); added to an older database when it is opened
_ADDED_COLUMNS = (("label", "TEXT"), ("status_reason", "TEXT"))
MAX_LABEL_CHARS = 80

ACTIVE_STATUSES = ("queued", "starting", "running")
#: a going run's status while no thermocouple reading reaches its estimate: live only (this server's, the frames');
#: the database keeps it "running" until it ends, and a run that ended blind is stored "degraded" (an ending)
DEGRADED = "degraded"
#: the columns of a RunRow, in its order (named: an older database has its added columns last, in any order)
_RUN_COLUMNS = "id, scenario, status, created_at, started_at, ended_at, latest, metrics, error, label, status_reason"


@dataclass(frozen=True)
class RunRow:
    id: str
    scenario: dict[str, Any]
    status: str
    created_at: float
    started_at: float | None
    ended_at: float | None
    latest: dict[str, Any] | None
    metrics: dict[str, Any] | None
    error: str | None
    label: str | None = None
    status_reason: str | None = None  # why the run ended so (twin.runs.outage.run_ending), once it ended


@dataclass(frozen=True)
class ChangeRow:
    id: int
    run_id: str
    kind: str
    body: dict[str, Any]
    requested_at: float
    status: str
    applied_t: float | None
    message: str | None


def clean_label(label: str | None) -> str | None:
    """A run's label as stored: one line with single spaces, ``None`` if blank; ``ValueError`` if longer than
    ``MAX_LABEL_CHARS`` or not printable.

    >>> clean_label("  fixed,\tTC4  middle "), clean_label(" ")
    ('fixed, TC4 middle', None)
    """
    text = " ".join((label or "").split())
    if len(text) > MAX_LABEL_CHARS:
        raise ValueError(f"at most {MAX_LABEL_CHARS} characters, got {len(text)}")
    if any(not c.isprintable() for c in text):
        raise ValueError("only printable characters")
    return text or None


def _loads(text: str | None) -> Any:
    return None if text is None else json.loads(text)


class RunRepository:
    """Thread-safe access to ``runs.sqlite3``."""

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.executescript(_SCHEMA)
        have = {r[1] for r in self._db.execute("PRAGMA table_info(runs)")}
        for name, kind in _ADDED_COLUMNS:
            if name not in have:
                self._db.execute(f"ALTER TABLE runs ADD COLUMN {name} {kind}")

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def _exec(self, sql: str, args: tuple[Any, ...] = ()) -> sqlite3.Cursor:
        with self._lock:
            return self._db.execute(sql, args)

    def create_run(self, run_id: str, scenario_json: str, status: str = "queued") -> None:
        self._exec(
            "INSERT INTO runs (id, scenario, status, created_at) VALUES (?, ?, ?, ?)",
            (run_id, scenario_json, status, time.time()),
        )

    def set_status(self, run_id: str, status: str, *, error: str | None = None, reason: str | None = None) -> None:
        """A status change; an ending (any status but the active ones) with its end time, error and reason."""
        now = time.time()
        if status == "running":
            self._exec("UPDATE runs SET status=?, started_at=? WHERE id=?", (status, now, run_id))
        elif status in ACTIVE_STATUSES:
            self._exec("UPDATE runs SET status=? WHERE id=?", (status, run_id))
        else:
            self._exec(
                "UPDATE runs SET status=?, ended_at=?, error=COALESCE(?, error), "
                "status_reason=COALESCE(?, status_reason) WHERE id=?",
                (status, now, error, reason, run_id),
            )

    def save_progress(
        self, run_id: str, latest: dict[str, Any] | None, metrics: dict[str, Any] | None = None
    ) -> None:
        """Store the latest values (and metrics, when known) as JSON."""
        self._exec(
            "UPDATE runs SET latest=COALESCE(?, latest), metrics=COALESCE(?, metrics) WHERE id=?",
            (
                None if latest is None else json.dumps(latest),
                None if metrics is None else json.dumps(metrics),
                run_id,
            ),
        )

    def set_label(self, run_id: str, label: str | None) -> None:
        """A user's name for the run (``None`` or empty: none)."""
        self._exec("UPDATE runs SET label=? WHERE id=?", (label or None, run_id))

    def delete_run(self, run_id: str) -> bool:
        """Remove the run and its changes (a user's delete, retention); ``False`` if there was no such run."""
        with self._lock:
            self._db.execute("BEGIN")
            try:
                self._db.execute("DELETE FROM changes WHERE run_id=?", (run_id,))
                gone = self._db.execute("DELETE FROM runs WHERE id=?", (run_id,)).rowcount
                self._db.execute("COMMIT")
            except Exception:
                self._db.execute("ROLLBACK")
                raise
        return bool(gone)

    def get(self, run_id: str) -> RunRow | None:
        cur = self._exec(f"SELECT {_RUN_COLUMNS} FROM runs WHERE id=?", (run_id,))
        row = cur.fetchone()
        return None if row is None else self._run(row)

    def list_runs(self, limit: int = 200) -> list[RunRow]:
        cur = self._exec(f"SELECT {_RUN_COLUMNS} FROM runs ORDER BY created_at DESC LIMIT ?", (limit,))
        return [self._run(r) for r in cur.fetchall()]

    def runs_created_before(self, cutoff: float) -> list[RunRow]:
        cur = self._exec(f"SELECT {_RUN_COLUMNS} FROM runs WHERE created_at < ? ORDER BY created_at", (cutoff,))
        return [self._run(r) for r in cur.fetchall()]

    def count_active(self) -> int:
        marks = ",".join("?" * len(ACTIVE_STATUSES))
        cur = self._exec(f"SELECT COUNT(*) FROM runs WHERE status IN ({marks})", ACTIVE_STATUSES)
        return int(cur.fetchone()[0])

    def mark_interrupted(self) -> list[str]:
        """After a restart: runs still marked active did not end cleanly; call them interrupted."""
        marks = ",".join("?" * len(ACTIVE_STATUSES))
        cur = self._exec(f"SELECT id FROM runs WHERE status IN ({marks})", ACTIVE_STATUSES)
        ids = [r[0] for r in cur.fetchall()]
        for run_id in ids:
            self._exec(
                "UPDATE runs SET status='interrupted', ended_at=COALESCE(ended_at, ?), "
                "error=COALESCE(error, 'the server stopped while the run was going'), "
                "status_reason=COALESCE(status_reason, 'the server stopped while the run was going') WHERE id=?",
                (time.time(), run_id),
            )
        return ids

    def set_ended_at(self, run_id: str, t: float) -> None:
        self._exec("UPDATE runs SET ended_at=? WHERE id=?", (t, run_id))

    def add_change(self, run_id: str, kind: str, body: dict[str, Any]) -> int:
        cur = self._exec(
            "INSERT INTO changes (run_id, kind, body, requested_at, status) VALUES (?, ?, ?, ?, 'pending')",
            (run_id, kind, json.dumps(body), time.time()),
        )
        return int(cur.lastrowid or 0)

    def finish_change(self, change_id: int, status: str, applied_t: float | None, message: str | None) -> None:
        self._exec(
            "UPDATE changes SET status=?, applied_t=?, message=? WHERE id=?",
            (status, applied_t, message, change_id),
        )

    def changes(self, run_id: str) -> list[ChangeRow]:
        cur = self._exec("SELECT * FROM changes WHERE run_id=? ORDER BY id", (run_id,))
        return [
            ChangeRow(
                id=r[0], run_id=r[1], kind=r[2], body=json.loads(r[3]), requested_at=r[4],
                status=r[5], applied_t=r[6], message=r[7],
            )
            for r in cur.fetchall()
        ]

    @staticmethod
    def _run(r: tuple[Any, ...]) -> RunRow:
        return RunRow(
            id=r[0], scenario=json.loads(r[1]), status=r[2], created_at=r[3], started_at=r[4],
            ended_at=r[5], latest=_loads(r[6]), metrics=_loads(r[7]), error=r[8], label=r[9], status_reason=r[10],
        )
