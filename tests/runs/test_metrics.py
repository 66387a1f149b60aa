"""Metrics of product.md on hand-made time series whose answers are known in closed form."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from twin.physics.fillet import Fillet
from twin.runs.metrics import METRIC_KEYS, compute_metrics, window


def _series(n_t: int = 201, t_E: float = 10.0, t_end: float | None = None) -> dict:
    t = np.linspace(0.0, 2 * t_E if t_end is None else t_end, n_t)
    x = (np.arange(26) + 0.5) * 0.4 / 26
    y = (np.arange(17) + 0.5) * 0.2 / 17
    T_ref = np.minimum(300 + 80 * t, 1100.0)
    field = np.broadcast_to(T_ref[:, None, None], (n_t, 17, 26)).copy()
    return dict(
        t=t, T_ref=T_ref, T_mean_hat=T_ref.copy(), tc=np.repeat(T_ref[:, None], 4, 1),
        tc_hat=np.repeat(T_ref[:, None], 4, 1), t_field=t, field_hat=field, field_true=field.copy(),
        x=x, y=y, L_s=0.4, W_s=0.2, t_E=t_E, setpoint=1100.0,
    )


def test_perfect_run_has_zero_errors():
    m = compute_metrics(_series())
    assert all(v == pytest.approx(0.0, abs=1e-12) for v in m.values()), m


def test_windows_follow_product_definition():
    t = np.linspace(0, 20, 201)
    assert window(t, 10.0, "transient").sum() == 101  # 0..10 s at 0.1 s
    assert window(t, 10.0, "steady").sum() == 51  # 15..20 s
    assert window(t, 10.0, "after_start").sum() == 191  # >= 1 s


def test_known_offsets_are_reported_relative_to_setpoint():
    ts = _series()
    steady = window(ts["t"], ts["t_E"], "steady")
    ts["T_mean_hat"] = ts["T_mean_hat"] + np.where(steady, 5.5, 11.0)  # 0.5 % steady, 1 % transient
    ts["tc"][:, 3] += 22.0  # 2 % everywhere
    # one hot spot of +44 K in the fillet centre: sup-norm 4 %
    ts["field_hat"][:, 8, 13] += 44.0
    m = compute_metrics(ts)
    assert m["mean_error_steady_max"] == pytest.approx(0.005)
    assert m["mean_error_transient_max"] == pytest.approx(0.01)
    assert m["tc4_error_steady_max"] == pytest.approx(0.02)
    assert m["tc123_error_max"] == pytest.approx(0.0)
    assert m["inhomogeneity_steady"] == pytest.approx(0.04)
    assert m["field_estimation_error_steady_max"] == pytest.approx(0.04)
    assert m["true_inhomogeneity_steady"] == pytest.approx(0.0)


def test_hot_spot_outside_fillet_is_ignored():
    ts = _series()
    ts["field_hat"][:, 0, 0] += 100.0  # corner cell, outside 0.25-0.75 L_s x 0.2-0.8 W_s
    assert compute_metrics(ts)["inhomogeneity_steady"] == pytest.approx(0.0)


def test_fillet_mask_counts_cells():
    x = (np.arange(26) + 0.5) / 26
    y = (np.arange(17) + 0.5) / 17
    fillet = Fillet.on_grid(x, y, 1.0, 1.0)
    mask = fillet.mask
    # x-centres in [0.25, 0.75]: i = 7..19 -> 13... checked by direct count below (independent loop)
    expected = sum(1 for xi in x for yj in y if 0.25 <= xi <= 0.75 and 0.2 <= yj <= 0.8)
    assert mask.sum() == expected
    assert fillet.sup(np.zeros((2, 17, 26)), np.array([1.0, 2.0])).tolist() == [1.0, 2.0]


def test_stopped_run_gives_nan_for_missing_windows():
    ts = _series()
    keep = ts["t"] <= 5.0
    for k in ("t", "T_ref", "T_mean_hat", "tc", "tc_hat", "t_field", "field_hat", "field_true"):
        ts[k] = ts[k][keep]
    m = compute_metrics(ts)
    assert np.isnan(m["mean_error_steady_max"]) and m["mean_error_transient_max"] == 0.0


def test_each_metric_sees_only_its_window():
    """Errors placed in one time span at a time, on a 0.05 s grid of a t_E = 10 s run that goes on to 2.5 t_E.

    Spans (product.md windows): start (t < t_E / 10: transient only, not after-start; 0.95 s is in it),
    between (t_E < t < 1.5 t_E: no window), steady (1.5..2 t_E), late (t > 2 t_E, a run longer than
    2 t_E: no window but after-start).  An error outside a metric's window must not change it.
    """
    t = _series(n_t=501, t_E=10.0, t_end=25.0)["t"]
    spans = {"start": t < 0.97, "between": (t > 10.02) & (t < 14.98), "steady": (t >= 15.0) & (t <= 20.0),
             "late": t > 20.02}
    expected_in = {  # metric -> spans it sees
        "mean_error_transient_max": {"start"},
        "mean_error_steady_max": {"steady"},
        "tc123_error_max": {"between", "steady", "late"},
        "tc4_error_transient_max": {"start"},
        "tc4_error_steady_max": {"steady"},
        "inhomogeneity_transient_max": {"start"},
        "inhomogeneity_steady": {"steady"},
        "true_inhomogeneity_steady": {"steady"},
        "true_mean_error_steady_max": {"steady"},
        "field_estimation_error_steady_max": {"steady"},
    }
    for span, sel in spans.items():
        ts = _series(n_t=501, t_E=10.0, t_end=25.0)
        ts["T_mean_hat"][sel] += 22.0  # 2 % of the 1100 K setpoint
        ts["tc"][sel] += 22.0  # every TC, so TC1..3 and TC4
        ts["field_hat"][sel, 8, 13] += 22.0  # fillet centre: 2 % sup-norm, 2 % estimation error
        ts["field_true"][sel] += 22.0  # the whole true field: 2 % mean error and sup-norm
        m = compute_metrics(ts)
        for key, seen in expected_in.items():
            assert m[key] == pytest.approx(0.02 if span in seen else 0.0, abs=1e-12), (span, key)


def test_true_field_metrics_are_relative_and_nan_without_truth():
    ts = _series()
    ts["field_true"][:, 8, 13] += 44.0  # a hot spot of the true field in the fillet centre: 4 %
    m = compute_metrics(ts)
    assert m["true_inhomogeneity_steady"] == pytest.approx(0.04)
    assert m["field_estimation_error_steady_max"] == pytest.approx(0.04)
    # 44 K on one cell of the fillet: the true mean error is 44 K x that cell's area weight / 1100 K
    w = Fillet.on_grid(ts["x"], ts["y"], ts["L_s"], ts["W_s"]).weights[8, 13]
    assert m["true_mean_error_steady_max"] == pytest.approx(44.0 * w / 1100.0, rel=1e-12)
    del ts["field_true"]  # a real furnace: no truth
    m2 = compute_metrics(ts)
    for k in ("true_inhomogeneity_steady", "true_mean_error_steady_max", "field_estimation_error_steady_max"):
        assert np.isnan(m2[k]), k
    assert {k: v for k, v in m2.items() if not np.isnan(v)} == {k: v for k, v in m.items() if "true" not in k
                                                                and k != "field_estimation_error_steady_max"}


def test_a_run_without_samples_gives_nan_everywhere():
    ts = _series()
    for k in ("t", "T_ref", "T_mean_hat", "tc", "tc_hat", "t_field", "field_hat", "field_true"):
        ts[k] = ts[k][:0]
    m = compute_metrics(ts)
    # product.md's keys, and a simulation's true transient mean error (issue 11), all NaN
    assert set(m) == {*METRIC_KEYS, "true_mean_error_transient_max"} and all(np.isnan(v) for v in m.values()), m


def test_true_transient_mean_error_is_that_of_the_true_field():
    """Oracle: a true field 22 K above the reference in the transient, 5.5 K in the steady window (2 % and
    0.5 % of 1100 K); the estimate is exact, so only the true-field metrics see it; no truth, no key."""
    ts = _series()
    transient = window(ts["t"], ts["t_E"], "transient")
    ts["field_true"] = ts["field_true"] + np.where(transient, 22.0, 5.5)[:, None, None]
    m = compute_metrics(ts)
    assert m["true_mean_error_transient_max"] == pytest.approx(0.02)
    assert m["true_mean_error_steady_max"] == pytest.approx(0.005)
    assert m["mean_error_transient_max"] == pytest.approx(0.0)
    del ts["field_true"]
    assert "true_mean_error_transient_max" not in compute_metrics(ts)


# ------------------------------------------------------------------ properties (hypothesis)
TEMPERATURE_KEYS = ("T_ref", "T_mean_hat", "tc", "tc_hat", "field_hat", "field_true")


def _perturbed(seed: int) -> dict:
    """A series with errors everywhere: mean, TCs, estimated and true fields (deterministic in seed)."""
    rng = np.random.default_rng(seed)
    ts = _series(n_t=81, t_E=4.0)
    n = ts["t"].size
    ts["T_mean_hat"] = ts["T_mean_hat"] + rng.normal(0, 8, n)
    ts["tc"] = ts["tc"] + rng.normal(0, 5, (n, 4))
    ts["field_hat"] = ts["field_hat"] + rng.normal(0, 20, ts["field_hat"].shape)
    ts["field_true"] = ts["field_true"] + rng.normal(0, 20, ts["field_true"].shape)
    return ts


@given(st.integers(0, 2**16), st.floats(-250.0, 600.0))
def test_metrics_do_not_change_when_every_temperature_and_the_reference_shift_together(seed, shift) -> None:
    """Every metric is a difference of two temperatures over the setpoint: a common offset cancels."""
    ts = _perturbed(seed)
    base = compute_metrics(ts)
    shifted = dict(ts, **{k: ts[k] + shift for k in TEMPERATURE_KEYS})
    again = compute_metrics(shifted)
    assert all(np.isfinite(v) and v > 0 for v in base.values()), base  # every metric sees an error
    for k, v in base.items():
        # offsets of up to 1.7e3 K on errors of ~1e1 K: rounding ~1e-13 K over the 1100 K setpoint
        assert again[k] == pytest.approx(v, rel=1e-9, abs=1e-12), k


@given(st.integers(0, 2**16), st.floats(0.2, 5.0))
def test_metrics_are_relative_to_the_setpoint(seed, factor) -> None:
    """Scaling every temperature, the reference and the setpoint together leaves the relative errors."""
    ts = _perturbed(seed)
    base = compute_metrics(ts)
    scaled = dict(ts, setpoint=ts["setpoint"] * factor, **{k: ts[k] * factor for k in TEMPERATURE_KEYS})
    again = compute_metrics(scaled)
    for k, v in base.items():
        assert again[k] == pytest.approx(v, rel=1e-9), k


def test_a_reference_change_moves_the_windows_and_the_scale():
    """After a reference change at t_c the windows are t_c..t_c+t_E (transient) and t_c+1.5..2 t_E (steady)
    of the new reference, and errors are relative to its setpoint (module docstring of twin.runs.metrics)."""
    from twin.events import RunChange, change_arrays

    ts = _series(n_t=401, t_E=10.0)  # 0..20 s at 0.05 s
    t = ts["t"]
    # a change at t = 4 s to 1000 K in 6 s: transient 4..10 s, steady 13..16 s
    ts.update(change_arrays([RunChange(4.0, "oscillation", {"enabled": True}),
                             RunChange(4.0, "reference", {"setpoint": 1000.0, "t_E": 6.0})]))
    # +20 K in 13..16 s only (the new steady window), +50 K in 16.5..20 s (the scenario's steady window)
    ts["T_mean_hat"] = ts["T_ref"] + np.where((t >= 13.0) & (t <= 16.0), 20.0, 0.0) + np.where(t >= 16.5, 50.0, 0.0)
    m = compute_metrics(ts)
    assert m["mean_error_steady_max"] == pytest.approx(20.0 / 1000.0)  # new window, new scale
    assert m["mean_error_transient_max"] == pytest.approx(0.0)
    # without the change the scenario's windows (15..20 s) and setpoint (1100 K) apply
    for k in ("change_t", "change_kind", "change_json"):
        del ts[k]
    assert compute_metrics(ts)["mean_error_steady_max"] == pytest.approx(50.0 / 1100.0)


def test_points_reference_change_takes_its_last_point():
    from twin.runs.metrics import windows_from

    w = windows_from(120.0, 1100.0, [(50.0, "reference", {"points": [[10.0, 900.0], [40.0, 950.0]]})])
    assert (w.t0, w.t_E, w.setpoint, w.steady) == (50.0, 40.0, 950.0, (110.0, 130.0))


def test_shadow_metrics_are_those_of_its_own_outputs():
    """A run with a shadow estimator (issue 11): ``shadow`` = the metrics of the same run with the shadow's
    outputs in place of the primary's (oracle: that run built by hand); the primary's keep their values.
    A calibrating primary's parameters end up in ``calibration``, not in the shadow's metrics."""
    ts = _series()
    ts["shadow_T_mean_hat"] = ts["T_mean_hat"] + 11.0  # 1 % everywhere
    ts["shadow_tc_hat"] = ts["tc_hat"] - 5.5  # 0.5 % at every TC
    ts["shadow_field_hat"] = ts["field_hat"] + 2.2
    ts["parameters"] = np.tile([-0.1, -0.05, np.nan], (len(ts["t"]), 1))
    ts["parameter_sigma"] = np.tile([0.01, 0.02, np.nan], (len(ts["t"]), 1))
    m = compute_metrics(ts)
    by_hand = _series()
    by_hand.update(T_mean_hat=ts["shadow_T_mean_hat"], tc_hat=ts["shadow_tc_hat"], field_hat=ts["shadow_field_hat"])
    assert m["shadow"] == pytest.approx(compute_metrics(by_hand))
    assert m["shadow"]["mean_error_steady_max"] == pytest.approx(0.01)
    assert m["shadow"]["tc4_error_steady_max"] == pytest.approx(0.005)
    assert m["mean_error_steady_max"] == pytest.approx(0.0)  # the primary's own
    assert m["calibration"] == {"lamp_efficiency": {"value": -0.1, "sigma": 0.01},
                                "emissivity": {"value": -0.05, "sigma": 0.02}}
    assert "calibration" not in m["shadow"]


# -- oscillation_amplitude: oracles from closed-form sinusoids --------------------------------------------------

def test_oscillation_amplitude_of_a_known_sinusoid_with_offset_and_harmonic():
    """e(t) = 3 + 2.5 sin(w t + 0.7) + 1.0 sin(2 w t) over 4 whole periods, sampled uniformly: the offset is
    fitted (its own column) and the 2nd harmonic is orthogonal to sin/cos(w t) over whole periods of uniform
    samples, so the amplitude at w is exactly 2.5 (to rounding)."""
    from twin.runs.metrics import oscillation_amplitude

    period = 4.5
    t = np.arange(0.0, 4 * period, 0.1)  # 45 samples a period, 180 in all
    w = 2 * np.pi / period
    e = 3.0 + 2.5 * np.sin(w * t + 0.7) + 1.0 * np.sin(2 * w * t)
    assert oscillation_amplitude(t, e, period) == pytest.approx(2.5, rel=1e-9)
    # a sinusoid plus offset is in the model's span: any window, whole periods or not, gives it exactly
    part = t < 1.37 * period
    assert oscillation_amplitude(t[part], (e - np.sin(2 * w * t))[part], period) == pytest.approx(2.5, rel=1e-9)
    # at another frequency there is (almost) nothing: the harmonic alone, at w, over whole periods
    assert oscillation_amplitude(t, np.sin(2 * w * t), period) == pytest.approx(0.0, abs=1e-9)
    # missing samples (NaN) are left out, not zeros: the same amplitude from the rest
    holes = e.copy()
    holes[::7] = np.nan
    assert oscillation_amplitude(t, holes - np.sin(2 * w * t), period) == pytest.approx(2.5, rel=1e-9)


def test_tc4_oscillation_amplitude_is_that_of_the_signed_error():
    """A run whose TC4 reading oscillates about the estimate with 2 K at the oscillation period (no bias): the
    metric is 2 K / setpoint.  Of the absolute error it was ~0 (|sin| has no component at the period)."""
    import json

    ts = _series(n_t=401, t_E=10.0, t_end=40.0)
    period = 4.0
    t = ts["t"]
    ts["tc"] = ts["tc"].copy()
    ts["tc"][:, 3] += 2.0 * np.sin(2 * np.pi * t / period)
    ts["eta"] = 0.01 * np.sin(2 * np.pi * t / period)
    ts["scenario"] = json.dumps({"oscillation": {"enabled": True, "period": period, "amplitude": 0.01}})
    m = compute_metrics(ts)
    assert m["tc4_error_oscillation_amplitude"] == pytest.approx(2.0 / 1100.0, rel=1e-6)
    assert m["tc4_error_steady_max"] == pytest.approx(2.0 / 1100.0, rel=1e-3)  # the peak, for comparison


def test_every_metric_a_run_writes_has_glossary_words_with_a_unit():
    """A run with every optional part (a truth, the reported sigma and NIS, an oscillation, calibration, a shadow
    estimator, TC status): each key of its metrics (and of its shadow's) has a name, a meaning and a unit in
    the glossary (GET /api/glossary), and only errors relative to the setpoint carry that unit (the dashboard
    shows those in K and %; a share is not a % of the setpoint).  Fails when a metric is added without words."""
    import json

    from twin.runs.metrics import RELATIVE, metric_glossary, run_metrics

    ts = _series()
    n_t = len(ts["t"])
    ts["field_sigma"] = np.ones_like(ts["field_hat"])
    ts["nis"] = np.ones(n_t)
    ts["eta"] = 0.01 * np.sin(2 * np.pi * ts["t"] / 4.0)
    ts["scenario"] = json.dumps({"oscillation": {"enabled": True, "period": 4.0}})
    ts["u"] = np.full((n_t, 6), 0.5)
    ts["parameters"] = np.zeros((n_t, 3))
    ts["parameter_sigma"] = np.full((n_t, 3), 0.01)
    ts["tc_status"] = np.zeros((n_t, 4), np.int8)
    for k in ("T_mean_hat", "tc_hat", "field_hat"):
        ts[f"shadow_{k}"] = ts[k].copy()
    ts["true_mean_lamps_off"] = np.full(10, float(ts["T_ref"][0]))  # a simulated furnace left alone
    m = run_metrics(ts)
    glossary = metric_glossary()
    written = set(m) - {"shadow"} | set(m["shadow"]) - {"shadow"}
    assert {"coverage_2sigma_steady", "tc4_error_oscillation_amplitude", "calibration", "late_samples",
            "full_power_steady_max", "true_mean_error_transient_max",
            "true_mean_lead_lamps_off_max"} <= written  # the series has every part
    for key in written:
        words = glossary[key]
        assert words["name"] and len(words["meaning"]) > 20 and words["unit"], key
    relative = {k for k, w in glossary.items() if w["unit"] == RELATIVE}
    assert set(METRIC_KEYS) | {"true_mean_error_transient_max", "tc4_error_oscillation_amplitude",
                               "true_mean_lead_lamps_off_max"} == relative
