"""What the run manager answers and raises: its exceptions (each one an HTTP status in ``backend.app``),
a started run, a live sample, the reference and oscillation in force."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from backend.storage.repository import ChangeRow
from backend.streaming.frames import SnapshotLike


class RunNotFound(LookupError):
    """No run with this id (404)."""


class RunNotActive(RuntimeError):
    """The run exists but is no longer running (409)."""


class TooManyRuns(RuntimeError):
    """``max_concurrent_runs`` runs are already going (429)."""


class InsufficientStorage(RuntimeError):
    """The data directory's quota or the disk's free space has no room for the run (507)."""


class LimitExceeded(ValueError):
    """The scenario asks for more than the furnace or the server allows (amplitude, run length, speed,
    a reference the furnace cannot follow, a furnace over OPC UA it may not or cannot reach) (422)."""


class PlantBusy(RuntimeError):
    """Another run already drives that furnace (409)."""


class RunIsActive(RuntimeError):
    """The run is still going, so it cannot be deleted (409)."""


class RequestConflict(RuntimeError):
    """A start request id came again with a different scenario (409)."""


@dataclass(frozen=True)
class Started:
    """A started run: its id, the feasibility warnings of its reference, and whether this answered a
    repeated request (the same request id: the run it started the first time)."""

    run_id: str
    warnings: tuple[str, ...] = ()
    replayed: bool = False


@dataclass(frozen=True)
class LiveSample:
    """The latest sample of a running run: its snapshot, sequence number and the run's status."""

    snapshot: SnapshotLike
    seq: int
    status: str
    wall_time: float = 0.0  # unix s when the sample was computed


@dataclass(frozen=True)
class InForce:
    """The reference, oscillation and injected faults a run uses now (after live changes), as JSON."""

    reference: dict[str, Any]
    oscillation: dict[str, Any]
    faults: list[dict[str, Any]] = field(default_factory=list)  # ``at`` in run time


def in_force(scenario: dict[str, Any], changes: list[ChangeRow]) -> InForce:
    """The scenario's reference, oscillation and faults, replaced by each applied change in turn (an ended run)."""
    current: dict[str, Any] = {"reference": scenario.get("reference") or {},
                               "oscillation": scenario.get("oscillation") or {},
                               "faults": list(scenario.get("faults") or [])}
    for ch in changes:
        if ch.status != "applied":
            continue
        if ch.kind == "faults":
            t = ch.applied_t or 0.0
            current["faults"] = [{**f, "at": float(f.get("at", 0.0)) + t} for f in ch.body.get("faults", [])]
        elif ch.kind in current:
            current[ch.kind] = ch.body
    return InForce(**current)
