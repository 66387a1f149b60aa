"""A run's time series as JSON for the dashboard's charts, its history and the comparison.

From the live loop while a run goes (:meth:`RunManager.live_series`: up to the latest sample, so a
page that connects mid-run shows everything so far), else from the run's ``timeseries.npz``.  The
scalar series are decimated to at most ``max_points`` samples (every k-th sample, the last one
always kept); alongside:

- ``inhomogeneity``: T_sup(t) = max over the fillet |T_hat - T_ref| (the paper's, the metric), and
  ``spread``: max over the fillet |T_hat - fillet mean| (the inhomogeneity about the mean), both K,
  at ``t_field`` (``twin.physics.fillet.Fillet``);
- ``saturated`` (per kept sample, per group): +1 if the group was at full power, -1 if off, at any
  sample since the previous kept one (``twin.control.saturation.bound_flags``);
- ``events`` (every event, ``{n, t, text, level}``), ``changes`` (the live changes applied),
  ``windows`` (the metric windows, from the last reference change: ``twin.runs.metrics.windows_of``);
- ``field``: the last estimated field; ``n_samples``, ``t_last``;
- with the estimate's uncertainty (issue 25): ``sigma_mean`` (K, decimated like the scalars) and
  ``field_sigma`` (the last field's standard deviation, N_y x N_x, K);
- with a calibrating estimator (``twin.runs.record.OPTIONAL_SERIES``): ``parameters`` and
  ``parameter_sigma`` as ``{name: [...]}`` (relative deviations, decimated like the scalars) for the
  calibrated names only (``twin.model.tables.PARAMETERS`` with a finite value in some sample);
- with a shadow estimator: ``shadow_T_mean_hat`` (K), ``shadow_tc_hat`` (K, per sample 4, decimated
  like the scalars) and ``shadow_field_delta``: the last shadow field minus the last estimated field
  (N_y x N_x, K).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from twin.control.saturation import bound_flags
from twin.events import load_changes, load_events
from twin.jsonable import jsonable
from twin.model.tables import PARAMETERS
from twin.physics.fillet import Fillet
from twin.runs.metrics import windows_of
from twin.runs.record import load_arrays
from twin.runs.series_store import has_parts, load_parts

SCALARS = ("t", "eta", "T_ref", "T_mean_hat", "tc", "tc_hat", "u", "u_ff")
SHADOW_SCALARS = ("shadow_T_mean_hat", "shadow_tc_hat")


def pick(n: int, max_points: int) -> np.ndarray:
    """Indices of every k-th of ``n`` samples (k so that at most ``max_points`` stay), the last one kept."""
    step = max(1, int(np.ceil(n / max_points)))
    idx = np.arange(0, n, step)
    if n and idx[-1] != n - 1:
        idx = np.append(idx, n - 1)
    return idx


def _bucket_flags(flags: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Per kept sample idx[k]: the flags of samples idx[k-1]+1 .. idx[k] combined (+1 wins over -1 over 0)."""
    if not len(idx):
        return np.zeros((0, flags.shape[1]), np.int8)
    starts = np.concatenate([[0], idx[:-1] + 1])
    top = np.maximum.reduceat(flags, starts, axis=0)
    bottom = np.minimum.reduceat(flags, starts, axis=0)
    return np.where(top > 0, 1, np.where(bottom < 0, -1, 0)).astype(np.int8)


def fillet_series(z: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_field, T_sup, spread) of every stored field (K); empty without fields."""
    if "field_hat" not in z or not len(z["field_hat"]):
        return np.zeros(0), np.zeros(0), np.zeros(0)
    fh = np.asarray(z["field_hat"], dtype=float)
    tf = np.asarray(z["t_field"], dtype=float)
    fillet = Fillet.on_grid(z["x"], z["y"], float(z["L_s"]), float(z["W_s"]))
    T_ref_f = np.interp(tf, z["t"], z["T_ref"])
    return tf, np.asarray(fillet.sup(fh, T_ref_f)), np.asarray(fillet.spread(fh))


def estimator_series(z: Mapping[str, Any], idx: np.ndarray) -> dict[str, Any]:
    """The calibrated parameters and the shadow estimator's series at the kept samples ``idx`` (module
    docstring); empty for a run without them."""
    out: dict[str, Any] = {}
    if "parameters" in z and len(z["parameters"]):
        values = np.asarray(z["parameters"], dtype=float).reshape(len(z["parameters"]), -1)
        sigma = (np.asarray(z["parameter_sigma"], dtype=float).reshape(values.shape) if "parameter_sigma" in z
                 else np.full(values.shape, np.nan))
        names = [(i, name) for i, name in enumerate(PARAMETERS) if np.isfinite(values[:, i]).any()]
        out["parameters"] = {name: values[idx, i] for i, name in names}
        out["parameter_sigma"] = {name: sigma[idx, i] for i, name in names}
    for k in SHADOW_SCALARS:
        if k in z and len(z[k]):
            out[k] = np.asarray(z[k], dtype=float)[idx]
    if "shadow_field_hat" in z and len(z["shadow_field_hat"]) and "field_hat" in z and len(z["field_hat"]):
        out["shadow_field_delta"] = (np.asarray(z["shadow_field_hat"][-1], dtype=float)
                                     - np.asarray(z["field_hat"][-1], dtype=float))
    return out


def series_json(z: Mapping[str, Any], max_points: int = 2000) -> dict[str, Any]:
    """The JSON of the module docstring from a time series in the ``timeseries.npz`` layout."""
    n = len(z["t"])
    idx = pick(n, max_points)
    out: dict[str, Any] = {k: np.asarray(z[k])[idx] for k in SCALARS if k in z}
    if "u" in z and n:
        out["saturated"] = _bucket_flags(bound_flags(z["u"]), idx)
    tf, sup, spread = fillet_series(z)
    if tf.size:
        fidx = pick(len(tf), max_points)
        out["t_field"], out["inhomogeneity"], out["spread"] = tf[fidx], sup[fidx], spread[fidx]
        out["field"] = np.asarray(z["field_hat"][-1], dtype=float)
        if "field_sigma" in z and len(z["field_sigma"]):
            out["field_sigma"] = np.asarray(z["field_sigma"][-1], dtype=float)
    if "sigma_mean" in z and len(z["sigma_mean"]):
        out["sigma_mean"] = np.asarray(z["sigma_mean"], dtype=float)[idx]
    out.update(estimator_series(z, idx))
    out["events"] = [{"n": k, "t": e.t, "text": e.text, "level": e.level, "kind": e.kind}
                     for k, e in enumerate(load_events(z))]
    out["changes"] = [{"t": c.t, "kind": c.kind, "body": c.body} for c in load_changes(z)]
    out["windows"] = windows_of(z).to_json()
    out["n_samples"] = n
    out["t_last"] = float(z["t"][-1]) if n else None
    return jsonable(out)


def load_series(path: Path, max_points: int = 2000) -> dict[str, Any]:
    """:func:`series_json` of a stored ``timeseries.npz``."""
    return series_json(load_arrays(path), max_points)


class NoSeries(LookupError):
    """The run has no samples yet (404)."""


def run_arrays(manager: Any, run_id: str) -> Mapping[str, Any]:
    """A run's time series: the live loop's while this server drives it, else its ``timeseries.npz``
    (``RunNotFound`` if there is no such run, :class:`NoSeries` before its first sample, ``ValueError`` /
    ``OSError`` for an unreadable file)."""
    manager.run(run_id)  # 404 unless the id comes from the database, before it names a folder
    live = manager.live_series(run_id)
    if live is not None:
        return live
    files = manager.files(run_id)
    if has_parts(files.folder):  # stored in parts, not yet consolidated (twin.runs.series_store)
        return load_parts(files.folder)
    path: Path = files.timeseries
    if not path.is_file():
        raise NoSeries(f"run {run_id} has no samples yet")
    return load_arrays(path)
