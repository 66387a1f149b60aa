"""A finished run's last sample for the 3D view, read back from its ``timeseries.npz``."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)


@dataclass
class StoredSnapshot:
    """The last sample of a finished run, read back from its ``timeseries.npz`` (a ``SnapshotLike``)."""

    t: float
    eta: float
    T_ref: float
    T_mean_hat: float
    field_hat: np.ndarray
    field_true: np.ndarray
    tc: np.ndarray
    tc_hat: np.ndarray
    u: np.ndarray
    u_ff: np.ndarray
    inhomogeneity: float
    true_mean: float
    true_inhomogeneity: float
    events: tuple[str, ...] = ()
    has_field: bool = True


def stored_snapshot(path: Path, shape: tuple[int, int]) -> StoredSnapshot | None:
    """The last estimated field (``field_hat[-1]``, N_y x N_x) and the last scalars of a run's time
    series (layout in product.md); ``None`` if the file is missing, empty or unreadable.  Without a
    stored field the plate shows the last fillet mean (``has_field=False``)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if "t" not in z.files or not len(z["t"]):
                return None

            def last(key: str, n: int | None = None) -> Any:
                if key in z.files and len(z[key]):
                    return np.asarray(z[key][-1], dtype=float)
                return np.full(n, np.nan) if n else float("nan")

            T_mean = float(last("T_mean_hat"))
            fh = z["field_hat"] if "field_hat" in z.files else None
            has_field = fh is not None and len(fh) > 0 and tuple(fh.shape[1:]) == tuple(shape)
            field = np.asarray(fh[-1], dtype=float) if has_field and fh is not None else np.full(shape, T_mean)
            return StoredSnapshot(
                t=float(last("t")), eta=float(np.nan_to_num(last("eta"))), T_ref=float(last("T_ref")),
                T_mean_hat=T_mean, field_hat=field, field_true=np.full(shape, np.nan),
                tc=last("tc", 4), tc_hat=last("tc_hat", 4), u=np.nan_to_num(last("u", 6)), u_ff=last("u_ff", 6),
                inhomogeneity=float("nan"), true_mean=float("nan"), true_inhomogeneity=float("nan"),
                has_field=has_field,
            )
    except (OSError, ValueError, KeyError, IndexError) as exc:
        log.warning("cannot read %s for the 3D view: %s", path, exc)
        return None
