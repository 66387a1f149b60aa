"""A run's stored time series as JSON for the dashboard's charts (from ``timeseries.npz``).

The scalar series are decimated to at most ``max_points`` samples (every k-th sample, the last
one always kept); the inhomogeneity T_sup(t) = max over the fillet |T_hat - T_ref| (product.md)
is recomputed from ``field_hat`` at ``t_field`` with ``twin.runs.metrics``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from backend.frames import json_safe
from twin.physics.fillet import Fillet
from twin.runs.record import load_arrays

SCALARS = ("t", "eta", "T_ref", "T_mean_hat", "tc", "tc_hat", "u", "u_ff")


def _pick(n: int, max_points: int) -> np.ndarray:
    step = max(1, int(np.ceil(n / max_points)))
    idx = np.arange(0, n, step)
    if n and idx[-1] != n - 1:
        idx = np.append(idx, n - 1)
    return idx


def load_series(path: Path, max_points: int = 2000) -> dict[str, Any]:
    """Decimated scalars, inhomogeneity and the last estimated field of one run."""
    z = load_arrays(path)
    n = len(z["t"])
    idx = _pick(n, max_points)
    out: dict[str, Any] = {k: z[k][idx] for k in SCALARS if k in z}
    if "field_hat" in z and len(z["field_hat"]):
        fh = np.asarray(z["field_hat"], dtype=float)
        tf = np.asarray(z["t_field"], dtype=float)
        fillet = Fillet.on_grid(z["x"], z["y"], float(z["L_s"]), float(z["W_s"]))
        T_ref_f = np.interp(tf, z["t"], z["T_ref"])
        fidx = _pick(len(tf), max_points)
        out["t_field"] = tf[fidx]
        out["inhomogeneity"] = np.asarray(fillet.sup(fh[fidx], T_ref_f[fidx]))
        out["field"] = fh[-1]
    out["n_samples"] = n
    return json_safe(out)
