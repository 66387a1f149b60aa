"""A finished run's last sample for the 3D view, read back from its ``timeseries.npz``."""

from __future__ import annotations

import logging
from pathlib import Path

from twin.runs.record import StoredSnapshot, last_snapshot, load_arrays

log = logging.getLogger(__name__)


def stored_snapshot(path: Path, shape: tuple[int, int]) -> StoredSnapshot | None:
    """The last sample of a run's stored time series (:func:`twin.runs.record.last_snapshot`); ``None`` if
    the file is missing, empty or unreadable.  Without a stored field of this grid the plate shows the
    last fillet mean."""
    try:
        snap = last_snapshot(load_arrays(path))
    except (OSError, ValueError, KeyError, IndexError) as exc:
        log.warning("cannot read %s for the 3D view: %s", path, exc)
        return None
    if snap is not None and snap.field_hat.shape != tuple(shape):
        log.warning("%s holds a field of %s cells, the furnace has %s", path, snap.field_hat.shape, shape)
        return None
    return snap
