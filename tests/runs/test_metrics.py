"""Metrics of product.md on hand-made time series whose answers are known in closed form."""

import numpy as np
import pytest

from twin.physics.fillet import Fillet
from twin.runs.metrics import compute_metrics, window


def _series(n_t: int = 201, t_E: float = 10.0) -> dict:
    t = np.linspace(0.0, 2 * t_E, n_t)
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


def test_a_reference_change_moves_the_windows_and_the_scale():
    """After a reference change at t_c the windows are t_c..t_c+t_E (transient) and t_c+1.5..2 t_E (steady)
    of the new reference, and errors are relative to its setpoint (module docstring of twin.runs.metrics)."""
    from twin.runs.record import RunChange, change_arrays

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
