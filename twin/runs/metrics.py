"""Run metrics (product.md) as pure functions of a run's time series.

All relative errors are divided by the setpoint T_ref(t_E).  Windows: transient
0 <= t <= t_E, steady 1.5 t_E <= t <= 2 t_E.

**A reference changed during the run** moves the windows: they count from the last reference
change (the first sample that used it, ``change_t`` in the time series), with that reference's
t_E (a points reference: the time of its last point) and setpoint (its last temperature), which
also divides the relative errors: transient t_c <= t <= t_c + t_E, steady
t_c + 1.5 t_E <= t <= t_c + 2 t_E (:func:`windows_of`).  Without a change t_c = 0 and the
scenario's t_E and setpoint apply, as in the paper.  ``tc123_error_max`` keeps the whole run
after the scenario's first t_E / 10.  An oscillation change does not move the windows.

The inhomogeneity is the paper's sup-norm (section 5.1)

    T_sup(t) = max over the fillet |T_hat(x, y, t) - T_ref(t)|,

and the fillet mean the area integral over the fillet, both from
:class:`twin.physics.fillet.Fillet` on the stored field grid, so that :func:`compute_metrics`
applied to a saved ``timeseries.npz`` (:mod:`twin.runs.record`) gives exactly the published
``metrics.json``.  A run without a true field (a real furnace) reports NaN (JSON null) for the
``true_*`` and field-estimation metrics.  :func:`late_samples` counts the samples with a reading that did
not come in time (a real-time furnace; ``tc_status`` code 2), 0 for a simulation; a run's metrics
(:meth:`twin.runs.record.RunRecord.metrics`) carry it beside the error metrics.

Example
-------
>>> import numpy as np
>>> t = np.linspace(0, 2.0, 21)
>>> bool(window(t, 1.0, "steady").sum() == 6)
True
>>> w = windows_from(120.0, 1100.0, [(100.0, "reference", {"setpoint": 1050.0, "t_E": 30.0})])
>>> w.transient, w.steady, w.setpoint
((100.0, 130.0), (145.0, 160.0), 1050.0)
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from twin.events import load_changes
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
#: a group at or above this fraction of u_max counts as at full power
FULL_POWER = 0.999
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


@dataclass(frozen=True)
class Windows:
    """The metric windows of a run: from ``t0`` (s, the last reference change, 0 without one) with that
    reference's ``t_E`` (s) and ``setpoint`` (K, the scale of the relative errors)."""

    t0: float
    t_E: float
    setpoint: float

    @property
    def transient(self) -> tuple[float, float]:
        return (self.t0, self.t0 + self.t_E)

    @property
    def steady(self) -> tuple[float, float]:
        return (self.t0 + 1.5 * self.t_E, self.t0 + 2.0 * self.t_E)

    def to_json(self) -> dict[str, Any]:
        return {"t0": self.t0, "t_E": self.t_E, "setpoint": self.setpoint,
                "transient": list(self.transient), "steady": list(self.steady)}


def _reference_end(body: Mapping[str, Any]) -> tuple[float, float]:
    """(t_E, setpoint) of a reference as JSON: a transition's, or a points reference's last point."""
    if "points" in body:
        t_last, T_last = body["points"][-1]
        return float(t_last), float(T_last)
    return float(body["t_E"]), float(body["setpoint"])


def windows_from(t_E: float, setpoint: float, changes: Iterable[tuple[float, str, Mapping[str, Any]]]) -> Windows:
    """The windows of a run whose scenario has ``t_E`` and ``setpoint``, after its live ``changes``
    ((t, kind, body) oldest first): the last reference change moves them (module docstring)."""
    out = Windows(0.0, float(t_E), float(setpoint))
    for t, kind, body in changes:
        if kind == "reference":
            tE, sp = _reference_end(body)
            out = Windows(float(t), tE, sp)
    return out


def windows_of(ts: Mapping[str, Any]) -> Windows:
    """The windows of a stored run (the ``timeseries.npz`` layout; ``change_*`` may be absent)."""
    return windows_from(float(ts["t_E"]), float(ts["setpoint"]),
                        ((c.t, c.kind, c.body) for c in load_changes(ts)))

#: each metric in words: (short name, what it measures); the dashboard, the report and the comparison
#: show these.  Values are relative to the setpoint of the windows (x 100 = %; x setpoint = K).
METRIC_WORDS: dict[str, tuple[str, str]] = {
    "mean_error_transient_max": (
        "Mean error, transient (max)",
        "largest |fillet mean of the estimate - reference| in the transient window"),
    "mean_error_steady_max": (
        "Mean error, steady (max)",
        "largest |fillet mean of the estimate - reference| in the steady window"),
    "tc123_error_max": (
        "TC1-3 error (max)",
        "largest |reading - estimate| at TC1, TC2, TC3 (the thermocouples the estimator uses), "
        "after the first tenth of t_E"),
    "tc4_error_transient_max": (
        "TC4 error, transient (max)",
        "largest |reading - estimate| at TC4, the validation thermocouple the estimator never sees, "
        "in the transient window"),
    "tc4_error_steady_max": (
        "TC4 error, steady (max)",
        "largest |reading - estimate| at TC4 (validation) in the steady window"),
    "inhomogeneity_transient_max": (
        "T_sup, transient (max)",
        "largest T_sup = max over the fillet |estimate - reference| (paper, section 5.1) in the transient window"),
    "inhomogeneity_steady": (
        "T_sup, steady (mean)",
        "mean of T_sup = max over the fillet |estimate - reference| over the steady window"),
    "true_inhomogeneity_steady": (
        "True T_sup, steady (mean)",
        "the same from the simulated furnace's true field (simulations only)"),
    "true_mean_error_steady_max": (
        "True mean error, steady (max)",
        "largest |true fillet mean - reference| in the steady window (simulations only)"),
    "field_estimation_error_steady_max": (
        "Field estimation error, steady (max)",
        "largest |estimate - true field| over the fillet in the steady window (simulations only)"),
}
#: the uncertainty metrics in words (not relative errors: shares and normalised squares)
UNCERTAINTY_WORDS: dict[str, tuple[str, str]] = {
    "coverage_2sigma_transient": (
        "2-sigma coverage, transient",
        "share of fillet cells x samples where the true field lies within +-2 sigma of the estimate, transient "
        "window (simulations only; 0.954 if the reported sigma is right and the errors Gaussian)"),
    "coverage_2sigma_steady": (
        "2-sigma coverage, steady",
        "the same in the steady window (simulations only)"),
    "nees_mean": (
        "NEES per cell, steady (mean)",
        "mean of ((estimate - true field) / sigma)^2 over the fillet and the steady window: 1 when the reported "
        "sigma is right, above 1 over-confident (simulations only)"),
    "nis_mean": (
        "NIS per reading (mean)",
        "mean of the normalised innovation squared of TC1-3 per reading against the reported covariance: 1 "
        "when consistent"),
}


#: the metrics a run has only in some configurations (:func:`_extras`, :func:`run_metrics`) in words
EXTRA_WORDS: dict[str, tuple[str, str]] = {
    "true_mean_error_transient_max": (
        "True mean error, transient (max)",
        "largest |true fillet mean - reference| in the transient window (simulations only)"),
    "tc4_error_oscillation_amplitude": (
        "TC4 error, oscillation amplitude",
        "amplitude of the signed TC4 error (reading - estimate) at the oscillation frequency over the steady "
        "window (oscillating runs only)"),
    "full_power_steady_max": (
        "Full power, steady (max share)",
        "largest share of the steady window's samples that any lamp group spends at full power (u >= 0.999)"),
    "true_mean_lead_lamps_off_max": (
        "Lamps-off bound, transient",
        "largest lead of the true fillet mean over the reference with every lamp off, in the first "
        "30 s: the same furnace left alone warms by itself (warm holders, gas), and lamp power only adds heat, so no "
        "controller's true transient error is below it (simulations only)"),
    "late_samples": (
        "Late samples",
        "samples with a TC reading that did not come in time (a real-time furnace; 0 for a simulation)"),
    "calibration": (
        "Calibration at the end",
        "a calibrating run's learned parameters at its end, each a value and its standard deviation, relative "
        "deviations from the model's nominal value (-0.1 = 10 % below)"),
}
#: the unit of a metric relative to the setpoint of its windows (x 100: %, x setpoint: K)
RELATIVE = "fraction of the setpoint"
#: each metric's unit (what its number is): relative errors, shares, normalised squares, counts
METRIC_UNITS: dict[str, str] = {
    **{k: RELATIVE for k in METRIC_KEYS},
    "true_mean_error_transient_max": RELATIVE,
    "tc4_error_oscillation_amplitude": RELATIVE,
    "coverage_2sigma_transient": "share of fillet cells x samples (0-1)",
    "coverage_2sigma_steady": "share of fillet cells x samples (0-1)",
    "nees_mean": "1 (normalised square; 1 when consistent)",
    "nis_mean": "1 (normalised square; 1 when consistent)",
    "full_power_steady_max": "share of the steady window's samples (0-1)",
    "true_mean_lead_lamps_off_max": RELATIVE,
    "late_samples": "samples (count)",
    "calibration": "fraction of the model's nominal value",
}


def metric_glossary() -> dict[str, dict[str, str]]:
    """Every metric a run can write (``metrics.json``; a shadow estimator's under ``shadow`` has the same keys) in
    words: ``{key: {"name", "meaning", "unit"}}``, the setpoint-relative errors first, in the report's order."""
    words = {**METRIC_WORDS, **EXTRA_WORDS, **UNCERTAINTY_WORDS}
    return {k: {"name": n, "meaning": m, "unit": METRIC_UNITS[k]} for k, (n, m) in words.items()}


def window(t: Array, t_E: float, which: Literal["transient", "steady", "after_start"],
           t0: float = 0.0) -> NDArray[np.bool_]:
    """Boolean mask of the transient (t0..t0+t_E), steady (t0+1.5..t0+2 t_E) or after-start
    (>= t_E/10 from the run's start) samples."""
    eps = 1e-9 * max(t_E, 1.0)
    if which == "transient":
        return (t >= t0 - eps) & (t <= t0 + t_E + eps)
    if which == "steady":
        return (t >= t0 + 1.5 * t_E - eps) & (t <= t0 + 2.0 * t_E + eps)
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
    t_E, setpoint`` and, for the ``true_*`` metrics, ``field_true``; the ``change_*`` of live changes
    move the windows (:func:`windows_of`).  Windows without samples give NaN (a run stopped early).
    Oscillating, calibrating and shadowed runs get more keys (:func:`_extras`).
    """
    t = np.asarray(ts["t"], float)
    t_E0 = float(ts["t_E"])  # the scenario's: tc123_error_max counts from its first tenth
    w = windows_of(ts)
    t0, t_E, scale = w.t0, w.t_E, w.setpoint
    T_ref = np.asarray(ts["T_ref"], float)
    tc = np.asarray(ts["tc"], float)
    tc_hat = np.asarray(ts["tc_hat"], float)
    mean_err = np.abs(np.asarray(ts["T_mean_hat"], float) - T_ref) / scale
    tc_err = np.abs(tc - tc_hat) / scale

    tr, st, after = window(t, t_E, "transient", t0), window(t, t_E, "steady", t0), window(t, t_E0, "after_start")

    # the fields enter only through the two windows: only their samples are read (a 1 h run's fields in
    # float64 took 40 MB in the run's process as it finished, for metrics of its first 2 t_E)
    tf_all = np.asarray(ts["t_field"], float)
    used = window(tf_all, t_E, "transient", t0) | window(tf_all, t_E, "steady", t0)
    tf = tf_all[used]
    fillet = Fillet.on_grid(np.asarray(ts["x"]), np.asarray(ts["y"]), float(ts["L_s"]), float(ts["W_s"]))
    ref_f = np.interp(tf, t, T_ref) if t.size else np.zeros_like(tf)
    f_hat = np.asarray(np.asarray(ts["field_hat"])[used], float)
    sup_hat = fillet.sup(f_hat, ref_f) / scale if tf.size else np.zeros(0)
    if "field_true" in ts and tf.size:
        f_true = np.asarray(np.asarray(ts["field_true"])[used], float)
        sup_true = fillet.sup(f_true, ref_f) / scale
        true_mean_err = np.abs(fillet.mean(f_true) - ref_f) / scale
        est_err = np.max(np.abs(f_hat - f_true)[..., fillet.mask], axis=-1) / scale
    else:  # no truth (a real furnace), or no samples
        sup_true = true_mean_err = est_err = np.full(tf.size, np.nan)
    trf, stf = window(tf, t_E, "transient", t0), window(tf, t_E, "steady", t0)
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
    if "field_true" in ts:  # the transient seen in the true field: what the estimated mean error hides
        out["true_mean_error_transient_max"] = _max(true_mean_err, trf)
    if "field_sigma" in ts:
        out.update(uncertainty_metrics(ts, used, trf, stf, fillet, after))
    tc4_signed = (tc[:, 3] - tc_hat[:, 3]) / scale if t.size else np.zeros(0)
    return _extras(ts, out, t, st, tc4_signed)


#: the uncertainty metrics (issue 25) of a run that records ``field_sigma``
UNCERTAINTY_KEYS = ("coverage_2sigma_transient", "coverage_2sigma_steady", "nees_mean", "nis_mean")


def uncertainty_metrics(ts: Mapping[str, Any], used: NDArray[np.bool_], trf: NDArray[np.bool_],
                        stf: NDArray[np.bool_], fillet: Fillet, after: NDArray[np.bool_]) -> dict[str, float]:
    """Is the reported uncertainty true (:mod:`twin.estimation.consistency`)?  ``coverage_2sigma_*``: share of
    the fillet's cells x field samples of the window with |field_hat - field_true| <= 2 field_sigma;
    ``nees_mean``: mean over the steady window's fields of the per-cell NEES over the fillet (1 when
    consistent); without a true field these are NaN.  ``nis_mean``: mean of ``nis`` (per reading, 1 when
    consistent) after the first t_E / 10.  ``used`` selects the fields of the two windows, ``trf``/``stf``
    those of each among them."""
    from twin.estimation.consistency import cell_nees, coverage

    out = {k: float("nan") for k in UNCERTAINTY_KEYS}
    if "nis" in ts and len(ts["nis"]):
        out["nis_mean"] = _mean(np.asarray(ts["nis"], float), after)
    if "field_true" not in ts or not used.any():
        return out
    sigma = np.asarray(np.asarray(ts["field_sigma"])[used], float)[..., fillet.mask]
    err = (np.asarray(np.asarray(ts["field_hat"])[used], float)
           - np.asarray(np.asarray(ts["field_true"])[used], float))[..., fillet.mask]
    out["coverage_2sigma_transient"] = coverage(err[trf], sigma[trf])
    out["coverage_2sigma_steady"] = coverage(err[stf], sigma[stf])
    if stf.any():
        out["nees_mean"] = float(np.mean(cell_nees(err[stf], 0.0, sigma[stf], np.ones(err.shape[-1], bool))))
    return out


def _extras(ts: Mapping[str, Any], out: dict[str, Any], t: Array, st: NDArray[np.bool_], tc4_signed: Array,
            ) -> dict[str, Any]:
    """The metrics a run has only in some configurations (``true_mean_error_transient_max``, a simulated
    furnace's, is added before): ``tc4_error_oscillation_amplitude`` (an oscillating
    run: the amplitude of the signed TC4 error's component at the oscillation frequency over the steady
    window, relative),
    ``calibration`` ({name: {"value", "sigma"}} at the end of a calibrating run), ``shadow`` (the shadow
    estimator's metrics) and ``full_power_steady_max`` (the largest fraction of the steady window any lamp group
    spends at full power, u >= :data:`FULL_POWER`) and, for a simulated furnace, ``true_mean_lead_lamps_off_max``
    (:func:`lamps_off_lead` of the header's ``true_mean_lamps_off`` over the samples before the first live change)."""
    if "true_mean_lamps_off" in ts and t.size:  # issue 26: what no controller can undercut, before a live change
        change = np.asarray(ts.get("change_t", np.zeros(0)), float)
        before = t < float(change.min()) if change.size else np.ones(t.size, bool)
        out["true_mean_lead_lamps_off_max"] = lamps_off_lead(
            np.asarray(ts["true_mean_lamps_off"], float), np.asarray(ts["T_ref"], float)[before], float(ts["setpoint"]))
    if "u" in ts and st.any():  # issue 26: no lamp group at full power for long in the steady window
        u_st = np.asarray(ts["u"], float)[st]
        out["full_power_steady_max"] = float(np.max(np.mean(u_st >= FULL_POWER, axis=0)))
    period = _oscillation_period(ts)
    if period is not None and t.size:
        # of the signed error: |e| of an error oscillating about zero has no component at the frequency
        # (|sin| repeats twice per period), so the absolute error hid an oscillation larger than the bias
        out["tc4_error_oscillation_amplitude"] = oscillation_amplitude(t[st], tc4_signed[st], period)
    if "parameters" in ts and len(ts["parameters"]):
        values, sigma = np.asarray(ts["parameters"][-1], float), np.asarray(ts["parameter_sigma"][-1], float)
        out["calibration"] = {name: {"value": float(values[i]), "sigma": float(sigma[i])}
                              for i, name in enumerate(PARAMETERS) if np.isfinite(values[i])}
    if all(f"shadow_{k}" in ts for k in SHADOW_OUTPUTS):
        # the run as the shadow saw it: its outputs in place of the primary's, no shadow of its own (else
        # this would recurse) and not the primary's calibration
        shadow = {k: v for k, v in ts.items()
                  if not k.startswith("shadow_") and k not in ("parameters", "parameter_sigma")}
        for k in SHADOW_OUTPUTS:
            shadow[k] = ts[f"shadow_{k}"]
        out["shadow"] = compute_metrics(shadow)
    return out


#: how long (s) from a run's start the furnace left with its lamps off is followed (``true_mean_lead_lamps_off_max``):
#: a cold plate's lead on a heating reference ends when the reference outruns it, about 12 s into the paper's run
LAMPS_OFF_WINDOW_S = 30.0


def lamps_off_lead(free_mean: Array, T_ref: Array, setpoint: float) -> float:
    """``true_mean_lead_lamps_off_max``: the largest lead (>= 0, fraction of ``setpoint``) of ``free_mean``, the true
    fillet mean of the furnace left with every lamp off (K, from the run's start, one per sample), over the reference
    at the same samples; only their common samples count.

    >>> lamps_off_lead(np.array([300.0, 303.0, 306.0]), np.array([298.0, 299.0, 310.0]), 1000.0)
    0.004
    """
    n = min(len(free_mean), len(T_ref))
    if n == 0:
        return 0.0
    return max(float(np.max(np.asarray(free_mean[:n], float) - np.asarray(T_ref[:n], float))) / float(setpoint), 0.0)


def run_metrics(ts: Mapping[str, Any]) -> dict[str, Any]:
    """What a run reports: :func:`compute_metrics` and ``late_samples`` (as a float, like the others)."""
    return {**compute_metrics(ts), "late_samples": float(late_samples(ts))}


def late_samples(ts: Mapping[str, Any]) -> int:
    """Samples with a missing (late or lost) TC reading, from ``tc_status`` (0 if the series is absent); a reading
    the link could not bring (``unlinked``: the link down or its subscription not yet made again) is the link's
    outage, which the run's events and status reason name, not a late sample."""
    from twin.runs.record import TC_STATUS_CODES

    status = np.asarray(ts.get("tc_status", np.zeros((0, 4))))
    return int(np.any(status == TC_STATUS_CODES["missing"], axis=-1).sum()) if status.size else 0
