"""The uncertainty metrics (coverage, NEES, NIS), the late samples and the windows as JSON, on hand-made series.

The series is :func:`tests.runs.test_metrics._series`'s (t_E = 10 s: transient 0-10 s, steady 15-20 s, NIS
after 1 s), with sigma and errors placed so that each answer is a count: the share of fillet cells x samples
inside +-2 sigma, the mean of (error / sigma)^2 over the fillet, the mean of the NIS series after t_E / 10.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.runs.test_metrics import _series
from twin.events import RunChange, change_arrays
from twin.physics.fillet import Fillet
from twin.runs.metrics import Windows, compute_metrics, late_samples, run_metrics, window, windows_from
from twin.runs.record import TC_STATUS_CODES


def _fillet_mask(ts: dict) -> np.ndarray:
    return Fillet.on_grid(ts["x"], ts["y"], ts["L_s"], ts["W_s"]).mask


def _with_sigma(ts: dict, sigma: float = 2.0) -> dict:
    ts["field_sigma"] = np.full_like(ts["field_hat"], sigma)
    ts["nis"] = np.ones(len(ts["t"]))
    return ts


def test_coverage_is_the_share_of_fillet_cells_and_samples_within_two_sigma() -> None:
    """sigma = 2 K.  Transient: the fillet's first two rows 5 K off (2.5 sigma, outside), the rest 3 K (inside),
    and at one sample in four every cell 4.5 K off; steady: exactly 2 sigma (inside, the bound counts) except
    one row at -4.1 K.  Cells outside the fillet and samples outside both windows are 100 K off: not counted."""
    ts = _with_sigma(_series())
    t = ts["t"]
    mask = _fillet_mask(ts)
    rows = np.flatnonzero(mask.any(axis=1))
    tr, st = window(t, 10.0, "transient"), window(t, 10.0, "steady")
    err = np.full(ts["field_hat"].shape, 100.0)
    err[tr] = 3.0
    err[np.ix_(tr, rows[:2])] = 5.0
    every4 = tr & (np.arange(len(t)) % 4 == 0)
    err[every4] = 4.5
    err[st] = 4.0
    err[np.ix_(st, rows[-1:])] = -4.1
    err[:, ~mask] = 100.0
    ts["field_hat"] = ts["field_true"] + err
    m = compute_metrics(ts)
    n_cells = mask.sum()
    cells_first_two = mask[rows[:2]].sum()
    n_tr, n_every4 = tr.sum(), every4.sum()
    inside_tr = (n_tr - n_every4) * (n_cells - cells_first_two)
    assert m["coverage_2sigma_transient"] == pytest.approx(inside_tr / (n_tr * n_cells))
    assert m["coverage_2sigma_steady"] == pytest.approx(1.0 - mask[rows[-1]].sum() / n_cells)
    # NEES over the steady window: the mean over the fillet of (e / sigma)^2
    nees = ((n_cells - mask[rows[-1]].sum()) * (4.0 / 2.0) ** 2 + mask[rows[-1]].sum() * (4.1 / 2.0) ** 2) / n_cells
    assert m["nees_mean"] == pytest.approx(nees)


def test_the_error_is_estimate_minus_truth_and_sigma_its_own_field() -> None:
    """A truth 3 K below the estimate with sigma = 1 K in the steady window and 4 K elsewhere: outside 2 sigma in
    the steady window only; the coverage follows sigma, not the temperature level (both fields near 1100 K)."""
    ts = _with_sigma(_series(), 4.0)
    st = window(ts["t"], 10.0, "steady")
    ts["field_sigma"][st] = 1.0
    ts["field_true"] = ts["field_hat"] - 3.0
    m = compute_metrics(ts)
    assert m["coverage_2sigma_transient"] == pytest.approx(1.0)
    assert m["coverage_2sigma_steady"] == pytest.approx(0.0)
    assert m["nees_mean"] == pytest.approx(9.0)


def test_nis_is_averaged_after_the_first_tenth_of_t_e() -> None:
    ts = _with_sigma(_series())
    after = window(ts["t"], 10.0, "after_start")
    ts["nis"] = np.where(after, 1.5, 40.0)  # the start (t < 1 s) does not count
    ts["nis"][np.flatnonzero(after)[::2]] = 0.5
    assert compute_metrics(ts)["nis_mean"] == pytest.approx(np.mean(ts["nis"][after]))
    assert not np.isclose(np.mean(ts["nis"][after]), np.mean(ts["nis"]))


def test_without_a_truth_only_nis_is_reported_and_without_nis_nothing() -> None:
    ts = _with_sigma(_series())
    del ts["field_true"]
    ts["nis"] = np.full(len(ts["t"]), 1.25)
    m = compute_metrics(ts)
    assert m["nis_mean"] == pytest.approx(1.25)
    assert np.isnan(m["coverage_2sigma_transient"]) and np.isnan(m["coverage_2sigma_steady"])
    assert np.isnan(m["nees_mean"])
    ts["nis"] = np.zeros(0)  # a recording without NIS samples
    assert np.isnan(compute_metrics(ts)["nis_mean"])
    bare = _series()  # no sigma, no NIS: the keys are not there at all (a run before issue 25)
    assert "nis_mean" not in compute_metrics(bare) and "coverage_2sigma_steady" not in compute_metrics(bare)


def test_a_run_stopped_in_the_transient_has_coverage_of_the_transient_only() -> None:
    ts = _with_sigma(_series(n_t=121, t_end=12.0))  # stopped at 12 s: no steady window
    ts["field_true"] = ts["field_hat"] + 1.0
    m = compute_metrics(ts)
    assert m["coverage_2sigma_transient"] == pytest.approx(1.0)
    assert np.isnan(m["coverage_2sigma_steady"]) and np.isnan(m["nees_mean"])


def test_late_samples_count_samples_with_a_missing_reading_not_the_links_outage() -> None:
    n = 50
    status = np.full((n, 4), TC_STATUS_CODES["good"], np.int8)
    status[3, 1] = TC_STATUS_CODES["missing"]
    status[7, [0, 2, 3]] = TC_STATUS_CODES["missing"]  # one sample, three TCs: one late sample
    status[9, 3] = TC_STATUS_CODES["missing"]  # TC4 counts too
    status[20:30, :] = TC_STATUS_CODES["unlinked"]  # the link's outage: not late
    status[40, 2] = TC_STATUS_CODES["bad"]  # a bad reading is the TC's, not late
    assert late_samples({"tc_status": status}) == 3
    assert late_samples({}) == 0 and late_samples({"tc_status": np.zeros((0, 4), np.int8)}) == 0
    ts = _series()
    ts["tc_status"] = np.zeros((len(ts["t"]), 4), np.int8)
    ts["tc_status"][5, 0] = TC_STATUS_CODES["missing"]
    m = run_metrics(ts)
    assert m["late_samples"] == 1.0 and isinstance(m["late_samples"], float)


def test_windows_as_json() -> None:
    w = windows_from(120.0, 1100.0, [(30.0, "oscillation", {"enabled": True}),
                                     (60.0, "reference", {"setpoint": 1000.0, "t_E": 40.0})])
    assert w == Windows(60.0, 40.0, 1000.0)
    assert w.to_json() == {"t0": 60.0, "t_E": 40.0, "setpoint": 1000.0, "transient": [60.0, 100.0],
                           "steady": [120.0, 140.0]}
    points = windows_from(120.0, 1100.0, [(10.0, "reference", {"points": [[5.0, 900.0], [25.0, 950.0]]})])
    assert points.to_json() == {"t0": 10.0, "t_E": 25.0, "setpoint": 950.0, "transient": [10.0, 35.0],
                                "steady": [47.5, 60.0]}


# ----------------------------------------------------------------------------------------- the extras
def test_lamps_off_lead_is_the_largest_lead_over_the_common_samples() -> None:
    from twin.runs.metrics import lamps_off_lead

    free, ref = np.array([300.0, 303.0, 306.0]), np.array([298.0, 299.0, 310.0])
    assert lamps_off_lead(free, ref, 1000.0) == pytest.approx(0.004)  # 303 - 299 K of 1000 K
    assert lamps_off_lead(free, ref[:2], 500.0) == pytest.approx(0.008)  # only the common samples
    assert lamps_off_lead(free[:1], ref, 1000.0) == pytest.approx(0.002)
    assert lamps_off_lead(ref - 5.0, ref, 1000.0) == 0.0  # always behind: no lead, never negative
    assert lamps_off_lead(np.zeros(0), ref, 1000.0) == 0.0


def test_the_lamps_off_lead_counts_only_before_the_first_live_change() -> None:
    """The lamps-off run is the furnace left alone from the start with the *starting* reference: after a live change
    its comparison means nothing.  Lead 8 K at 2 s, 30 K at 6 s (after an oscillation switch at 5 s)."""
    ts = _series()
    free = ts["T_ref"].copy()
    free[20] += 8.0
    free[60] += 30.0
    ts["true_mean_lamps_off"] = free
    assert compute_metrics(ts)["true_mean_lead_lamps_off_max"] == pytest.approx(30.0 / 1100.0)
    ts.update(change_arrays([RunChange(5.0, "oscillation", {"enabled": True}),
                             RunChange(12.0, "oscillation", {"enabled": False})]))
    assert compute_metrics(ts)["true_mean_lead_lamps_off_max"] == pytest.approx(8.0 / 1100.0)
    free[50] += 20.0  # at t = 5.0 s, the change's own sample: already after it
    assert compute_metrics(ts)["true_mean_lead_lamps_off_max"] == pytest.approx(8.0 / 1100.0)


def test_full_power_steady_max_is_the_largest_share_of_one_group() -> None:
    """Three groups over the steady window (51 samples): G1 at full power in 10, G2 in 20 (at exactly 0.999, which
    counts), G3 at 0.998 throughout (does not).  Outside the window every group is at full power."""
    ts = _series()
    n_t = len(ts["t"])
    st = np.flatnonzero(window(ts["t"], 10.0, "steady"))
    u = np.ones((n_t, 3))
    u[st] = [0.5, 0.5, 0.998]
    u[st[:10], 0] = 1.0
    u[st[-20:], 1] = 0.999
    ts["u"] = u
    assert compute_metrics(ts)["full_power_steady_max"] == pytest.approx(20 / 51)


def test_the_calibration_is_the_last_sample_of_each_parameter_estimated() -> None:
    ts = _series()
    n_t = len(ts["t"])
    p = np.linspace(0.0, 1.0, n_t)[:, None] * np.array([[-0.1, 0.05, np.nan]])
    ts["parameters"], ts["parameter_sigma"] = p, np.abs(p) / 10.0 + np.array([0.01, 0.02, 0.03])
    cal = compute_metrics(ts)["calibration"]
    assert cal == {"lamp_efficiency": {"value": pytest.approx(-0.1), "sigma": pytest.approx(0.02)},
                   "emissivity": {"value": pytest.approx(0.05), "sigma": pytest.approx(0.025)}}  # convection: NaN


def test_the_signed_tc4_error_of_an_oscillating_run_keeps_its_sign() -> None:
    """TC4 reads 1 K sin(2 pi t / 4 s) below the reference and its estimate 2 K above: the error's amplitude is
    3 K (their sum would oscillate by 1 K)."""
    import json

    ts = _series()
    ts["eta"] = 0.01 * np.sin(2 * np.pi * ts["t"] / 4.0)
    ts["scenario"] = json.dumps({"oscillation": {"enabled": True, "period": 4.0}})
    ts["tc"][:, 3] -= 1.0 * np.sin(2 * np.pi * ts["t"] / 4.0)
    ts["tc_hat"][:, 3] += 2.0 * np.sin(2 * np.pi * ts["t"] / 4.0)
    assert compute_metrics(ts)["tc4_error_oscillation_amplitude"] == pytest.approx(3.0 / 1100.0, rel=1e-3)
    ts["scenario"] = json.dumps({"oscillation": {"enabled": False, "period": 4.0}})
    assert "tc4_error_oscillation_amplitude" not in compute_metrics(ts)


def test_the_field_windows_move_with_a_live_reference_change() -> None:
    """A reference change at 10 s to 1000 K with t_E = 10 s: the windows are 10-20 s and 25-30 s and the errors
    are relative to 1000 K.  A hot spot of 50 K at 22 s (between them) is not counted, one of 20 K at 27 s is."""
    ts = _series(n_t=301, t_end=30.0)
    t = ts["t"]
    ts["T_ref"] = np.where(t < 10.0, ts["T_ref"], 1000.0)
    ts["T_mean_hat"] = ts["T_ref"].copy()
    ts["field_hat"] = np.broadcast_to(ts["T_ref"][:, None, None], ts["field_hat"].shape).copy()
    ts["field_true"] = ts["field_hat"].copy()
    ts["tc"] = ts["tc_hat"] = np.repeat(ts["T_ref"][:, None], 4, 1)
    ts.update(change_arrays([RunChange(10.0, "reference", {"setpoint": 1000.0, "t_E": 10.0})]))
    ts["field_hat"][220, 8, 13] += 50.0
    ts["field_hat"][270, 8, 13] += 20.0
    m = compute_metrics(ts)
    assert m["field_estimation_error_steady_max"] == pytest.approx(0.02)
    assert m["inhomogeneity_transient_max"] == pytest.approx(0.0)
