"""Run metrics (product.md) as pure functions of a run's time series.

All relative errors are divided by the setpoint T_ref(t_E).  Windows: transient
0 <= t <= t_E, steady 1.5 t_E <= t <= 2 t_E.  The inhomogeneity is the paper's
sup-norm (section 5.1)

    T_sup(t) = max over the fillet |T_hat(x, y, t) - T_ref(t)|,

and the fillet mean the area integral over the fillet, both from
:class:`twin.physics.fillet.Fillet` on the stored field grid, so that :func:`compute_metrics`
applied to a saved ``timeseries.npz`` (:mod:`twin.runs.record`) gives exactly the published
``metrics.json``.  A run without a true field (a real furnace) reports NaN (JSON null) for the
``true_*`` and field-estimation metrics.

Example
-------
>>> import numpy as np
>>> t = np.linspace(0, 2.0, 21)
>>> bool(window(t, 1.0, "steady").sum() == 6)
True
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from twin.model.tables import PARAMETERS  # the order of the record's ``parameters``
from twin.physics.fillet import Fillet

Array = NDArray[np.float64]

METRIC_KEYS = (
    "mean_error_transient_max",
    "mean_error_steady_max",
    "tc123_error_max",
    "tc4_error_transient_max",
    "tc4_error_steady_max",
    "inhomogeneity_transient_max",
    "inhomogeneity_steady",
    "true_inhomogeneity_steady",
    "true_mean_error_steady_max",
    "field_estimation_error_steady_max",
)
#: the estimator outputs a shadow estimator records under ``shadow_<key>`` (twin.runs.record)
SHADOW_OUTPUTS = ("T_mean_hat", "tc_hat", "field_hat")


def oscillation_amplitude(t: Array, e: Array, period: float) -> float:
    """Amplitude of the component of e(t) at the frequency 1/period: sqrt(a^2 + b^2) of the least-squares
    fit e ~ a sin(w t) + b cos(w t) + c, w = 2 pi / period (NaN with fewer than 3 finite samples)."""
    ok = np.isfinite(e)
    if ok.sum() < 3:
        return float("nan")
    w = 2.0 * np.pi / period
    X = np.column_stack([np.sin(w * t[ok]), np.cos(w * t[ok]), np.ones(int(ok.sum()))])
    (a, b, _), *_ = np.linalg.lstsq(X, e[ok], rcond=None)
    return float(np.hypot(a, b))


def _oscillation_period(ts: Mapping[str, Any]) -> float | None:
    """The scenario's oscillation period (s) if the run oscillated (from the recorded scenario and eta)."""
    import json

    if "scenario" not in ts or not np.any(np.asarray(ts.get("eta", [0.0])) != 0.0):
        return None
    osc = json.loads(str(ts["scenario"])).get("oscillation") or {}
    return float(osc["period"]) if osc.get("enabled") and osc.get("period") else None


def window(t: Array, t_E: float, which: Literal["transient", "steady", "after_start"]) -> NDArray[np.bool_]:
    """Boolean mask of the transient (0..t_E), steady (1.5..2 t_E) or after-start (>= t_E/10) samples."""
    eps = 1e-9 * max(t_E, 1.0)
    if which == "transient":
        return (t >= -eps) & (t <= t_E + eps)
    if which == "steady":
        return (t >= 1.5 * t_E - eps) & (t <= 2.0 * t_E + eps)
    return t >= t_E / 10 - eps


def _max(values: Array, sel: NDArray[np.bool_]) -> float:
    v = np.asarray(values, float)[sel]
    v = v[np.isfinite(v)]
    return float(np.max(v)) if v.size else float("nan")


def _mean(values: Array, sel: NDArray[np.bool_]) -> float:
    v = np.asarray(values, float)[sel]
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else float("nan")


def compute_metrics(ts: Mapping[str, Any]) -> dict[str, Any]:
    """The product.md metrics from a time-series mapping (the ``timeseries.npz`` layout).

    Needs ``t, T_ref, T_mean_hat, tc (n,4), tc_hat (n,4), t_field, field_hat, x, y, L_s, W_s,
    t_E, setpoint`` and, for the ``true_*`` metrics, ``field_true``.  Windows without samples give
    NaN (a run stopped early).  Oscillating, calibrating and shadowed runs get more keys (:func:`_extras`).
    """
    t = np.asarray(ts["t"], float)
    t_E = float(ts["t_E"])
    scale = float(ts["setpoint"])
    T_ref = np.asarray(ts["T_ref"], float)
    tc = np.asarray(ts["tc"], float)
    tc_hat = np.asarray(ts["tc_hat"], float)
    mean_err = np.abs(np.asarray(ts["T_mean_hat"], float) - T_ref) / scale
    tc_err = np.abs(tc - tc_hat) / scale

    tr, st, after = window(t, t_E, "transient"), window(t, t_E, "steady"), window(t, t_E, "after_start")

    tf = np.asarray(ts["t_field"], float)
    fillet = Fillet.on_grid(np.asarray(ts["x"]), np.asarray(ts["y"]), float(ts["L_s"]), float(ts["W_s"]))
    ref_f = np.interp(tf, t, T_ref) if t.size else np.zeros_like(tf)
    f_hat = np.asarray(ts["field_hat"], float)
    sup_hat = fillet.sup(f_hat, ref_f) / scale if tf.size else np.zeros(0)
    if "field_true" in ts and tf.size:
        f_true = np.asarray(ts["field_true"], float)
        sup_true = fillet.sup(f_true, ref_f) / scale
        true_mean_err = np.abs(fillet.mean(f_true) - ref_f) / scale
        est_err = np.max(np.abs(f_hat - f_true)[..., fillet.mask], axis=-1) / scale
    else:  # no truth (a real furnace), or no samples
        sup_true = true_mean_err = est_err = np.full(tf.size, np.nan)
    trf, stf = window(tf, t_E, "transient"), window(tf, t_E, "steady")
    out: dict[str, Any] = {
        "mean_error_transient_max": _max(mean_err, tr),
        "mean_error_steady_max": _max(mean_err, st),
        "tc123_error_max": _max(tc_err[:, :3].max(axis=1) if t.size else np.zeros(0), after),
        "tc4_error_transient_max": _max(tc_err[:, 3] if t.size else np.zeros(0), tr),
        "tc4_error_steady_max": _max(tc_err[:, 3] if t.size else np.zeros(0), st),
        "inhomogeneity_transient_max": _max(sup_hat, trf),
        "inhomogeneity_steady": _mean(sup_hat, stf),
        "true_inhomogeneity_steady": _mean(sup_true, stf),
        "true_mean_error_steady_max": _max(true_mean_err, stf),
        "field_estimation_error_steady_max": _max(est_err, stf),
    }
    return _extras(ts, out, t, st, tc_err)


def _extras(ts: Mapping[str, Any], out: dict[str, Any], t: Array, st: NDArray[np.bool_], tc_err: Array,
            ) -> dict[str, Any]:
    """The metrics a run has only in some configurations: ``tc4_error_oscillation_amplitude`` (an oscillating
    run: the TC4 error's component at the oscillation frequency over the steady window, relative),
    ``calibration`` ({name: {"value", "sigma"}} at the end of a calibrating run) and ``shadow`` (the shadow
    estimator's metrics)."""
    period = _oscillation_period(ts)
    if period is not None and t.size:
        out["tc4_error_oscillation_amplitude"] = oscillation_amplitude(t[st], tc_err[st, 3], period)
    if "parameters" in ts and len(ts["parameters"]):
        values, sigma = np.asarray(ts["parameters"][-1], float), np.asarray(ts["parameter_sigma"][-1], float)
        out["calibration"] = {name: {"value": float(values[i]), "sigma": float(sigma[i])}
                              for i, name in enumerate(PARAMETERS) if np.isfinite(values[i])}
    if all(f"shadow_{k}" in ts for k in SHADOW_OUTPUTS):
        shadow = dict(ts)
        for k in SHADOW_OUTPUTS:
            shadow[k] = ts[f"shadow_{k}"]
        out["shadow"] = {k: v for k, v in compute_metrics(shadow).items() if k != "calibration"}
    return out
