"""GET /api/runs/{id}/series with the estimators' optional series (issue 11): the calibrated parameters and
their sigmas per name, decimated like the scalars, and the shadow estimator's fillet mean, TC estimates and
last field difference.  The oracle is the numbers put into the hand-built arrays."""

from __future__ import annotations

import json

import numpy as np
import pytest

from backend.streaming.series import load_series, series_json
from twin.runs.record import RunHeader, RunRecord, Snapshot

N_Y, N_X = 2, 3
KEPT = [0, 3, 6]  # pick(7, 3): every ceil(7 / 3) = 3rd sample, the last one (6) is one of them


def _arrays(n: int = 7, *, calibrated: bool = True, shadow: bool = True) -> dict:
    """A run of n samples in the timeseries.npz layout; sample k has easily told-apart values."""
    k = np.arange(n, dtype=float)
    z = {
        "t": 0.1 * (k + 1), "eta": np.zeros(n), "T_ref": np.full(n, 900.0), "T_mean_hat": 800.0 + k,
        "tc": np.tile(900.0 + k[:, None], (1, 4)), "tc_hat": np.tile(899.0 + k[:, None], (1, 4)),
        "u": np.full((n, 6), 0.5), "u_ff": np.full((n, 6), 0.4),
        "x": np.array([0.01, 0.03, 0.05]), "y": np.array([0.005, 0.015]), "L_s": 0.06, "W_s": 0.02,
        "t_E": 10.0, "setpoint": 900.0,
        # field k: 800 + k everywhere plus a column pattern
        "field_hat": (800.0 + k[:, None, None] + np.array([0.0, 1.0, 2.0])[None, None, :]
                      + np.zeros((n, N_Y, N_X))).astype(np.float32),
    }
    z["t_field"] = z["t"].copy()
    if calibrated:
        # lamp efficiency -0.01 k, emissivity +0.002 k, convection not calibrated (NaN)
        z["parameters"] = np.stack([-0.01 * k, 0.002 * k, np.full(n, np.nan)], axis=1)
        z["parameter_sigma"] = np.stack([0.05 / (k + 1), 0.02 / (k + 1), np.full(n, np.nan)], axis=1)
    if shadow:
        z["shadow_T_mean_hat"] = 810.0 + k
        z["shadow_tc_hat"] = np.tile(898.0 + k[:, None], (1, 4)) + np.array([0.0, 0.1, 0.2, 0.3])
        # the shadow field: the estimate plus k * 0.5 K at the cell (row 1, column 2) only, so only the last
        # sample (k = 6) gives 3.0 K there
        bump = np.zeros((n, N_Y, N_X))
        bump[:, 1, 2] = 0.5 * k
        z["shadow_field_hat"] = (z["field_hat"].astype(float) + bump).astype(np.float32)
    return z


def test_calibrated_parameters_are_decimated_like_the_scalars_for_the_calibrated_names_only() -> None:
    out = series_json(_arrays(), max_points=3)
    assert out["t"] == pytest.approx([0.1, 0.4, 0.7])  # the scalars' samples: KEPT
    # convection was not calibrated (NaN throughout): it is not listed at all
    assert set(out["parameters"]) == {"lamp_efficiency", "emissivity"} == set(out["parameter_sigma"])
    assert out["parameters"]["lamp_efficiency"] == pytest.approx([-0.01 * k for k in KEPT])
    assert out["parameters"]["emissivity"] == pytest.approx([0.002 * k for k in KEPT])
    assert out["parameter_sigma"]["lamp_efficiency"] == pytest.approx([0.05 / (k + 1) for k in KEPT])
    assert out["parameter_sigma"]["emissivity"] == pytest.approx([0.02 / (k + 1) for k in KEPT])


def test_a_missing_sigma_is_null_and_a_partly_calibrated_column_is_kept() -> None:
    z = _arrays(shadow=False)
    z["parameter_sigma"][3, 0] = np.nan  # one sample without its sigma (kept sample 3)
    z["parameters"][:5, 2] = np.nan  # convection known only from sample 5 on: it counts as calibrated
    z["parameters"][5:, 2] = 0.03
    out = series_json(z, max_points=3)
    assert out["parameter_sigma"]["lamp_efficiency"][1] is None
    assert out["parameters"]["convection"] == [None, None, pytest.approx(0.03)]
    json.dumps(out, allow_nan=False)  # plain JSON: no NaN reaches the page


def test_shadow_series_are_decimated_and_the_field_delta_is_the_last_difference() -> None:
    out = series_json(_arrays(), max_points=3)
    assert out["shadow_T_mean_hat"] == pytest.approx([810.0 + k for k in KEPT])
    assert np.asarray(out["shadow_tc_hat"]) == pytest.approx(
        np.array([[898.0 + k + 0.1 * i for i in range(4)] for k in KEPT]))
    delta = np.asarray(out["shadow_field_delta"], dtype=float)
    expected = np.zeros((N_Y, N_X))
    expected[1, 2] = 0.5 * 6  # the last sample's bump, not the first's (0) or a mean over samples
    assert delta.shape == (N_Y, N_X) and delta == pytest.approx(expected, abs=1e-4)  # float32 fields


def test_a_run_without_calibration_or_shadow_has_none_of_these_keys() -> None:
    out = series_json(_arrays(calibrated=False, shadow=False), max_points=3)
    assert not {"parameters", "parameter_sigma", "shadow_T_mean_hat", "shadow_tc_hat",
                "shadow_field_delta"} & set(out)
    assert out["t"] == pytest.approx([0.1, 0.4, 0.7])  # the rest as before


def test_from_a_saved_run_record(tmp_path) -> None:
    """The keys the run record writes (twin.runs.record) reach the page through a saved timeseries.npz."""
    header = RunHeader(x=np.array([0.01, 0.03, 0.05]), y=np.array([0.005, 0.015]), tc_positions=np.zeros((4, 2)),
                       L_s=0.06, W_s=0.02, t_E=10.0, setpoint=900.0, group_names=("a",), scenario="{}")
    rec = RunRecord(header, has_truth=False)
    for j in range(4):
        field = np.full((N_Y, N_X), 800.0 + j)
        rec.append(Snapshot(
            j=j, t=0.1 * (j + 1), eta=0.0, T_ref=900.0, T_mean_hat=800.0 + j, field_hat=field, field_true=None,
            tc=np.full(4, 805.0 + j), tc_hat=np.full(4, 800.0 + j), u=np.zeros(1), u_ff=np.zeros(1),
            inhomogeneity=1.0, true_mean=None, true_inhomogeneity=None,
            parameters=np.array([-0.1 + 0.01 * j, np.nan, 0.2]), parameter_sigma=np.array([0.01, np.nan, 0.05]),
            shadow_T_mean_hat=790.0 + j, shadow_tc_hat=np.full(4, 801.0 + j), shadow_field_hat=field - 2.0 * j))
    rec.save(tmp_path / "timeseries.npz")
    out = load_series(tmp_path / "timeseries.npz")
    assert set(out["parameters"]) == {"lamp_efficiency", "convection"}  # emissivity: NaN, not calibrated
    assert out["parameters"]["lamp_efficiency"] == pytest.approx([-0.1, -0.09, -0.08, -0.07])
    assert out["parameter_sigma"]["convection"] == pytest.approx([0.05] * 4)
    assert out["shadow_T_mean_hat"] == pytest.approx([790.0, 791.0, 792.0, 793.0])
    assert np.asarray(out["shadow_tc_hat"])[:, 3] == pytest.approx([801.0, 802.0, 803.0, 804.0])
    assert np.asarray(out["shadow_field_delta"]) == pytest.approx(np.full((N_Y, N_X), -6.0))  # -2 K x j = 3
