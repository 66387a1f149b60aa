"""The estimate's uncertainty in a run's record, stream frame, OPC UA values and metrics (issue 25)."""

from __future__ import annotations

import numpy as np
import pytest

from backend.streaming.frames import frame_dict
from backend.streaming.opcua_results import frame_values, sample_values
from twin.config import small_config
from twin.physics.fillet import Fillet
from twin.runs.loop import ClosedLoop
from twin.runs.metrics import UNCERTAINTY_KEYS, compute_metrics
from twin.scenario import Scenario


@pytest.fixture(scope="module")
def run() -> tuple[ClosedLoop, list]:
    loop = ClosedLoop(small_config(), Scenario(duration=4.0, reference={"setpoint": 400.0, "t_E": 2.0}, seed=31))
    predict = loop.estimators.predict
    posterior: list[np.ndarray] = []

    def keep_posterior(u, eta):  # the covariance each snapshot reports: after the update, before the predict
        posterior.append(loop.estimator.reported_P.copy())
        predict(u, eta)

    loop.estimators.predict = keep_posterior  # type: ignore[method-assign]
    snaps = list(loop.run())
    loop.posterior = posterior  # type: ignore[attr-defined]
    return loop, snaps


def test_field_sigma_is_recorded_beside_the_estimate(run) -> None:
    loop, snaps = run
    ts = loop.timeseries()
    assert ts["field_sigma"].shape == ts["field_hat"].shape
    assert ts["sigma_mean"].shape == ts["nis"].shape == ts["nees"].shape == ts["t"].shape
    assert np.all(ts["field_sigma"] > 0) and np.all(ts["sigma_mean"] > 0)
    # the last sample's map is the reported covariance through the hat functions (an independent dense product)
    fe = loop.changes.current.model.fe
    P = loop.posterior[-1]
    dense = np.sqrt(np.einsum("ci,ij,cj->c", fe.M_theta, P, fe.M_theta) + loop.uncertainty.representation_var)
    np.testing.assert_allclose(snaps[-1].field_sigma.ravel(), dense, rtol=1e-10)
    np.testing.assert_allclose(ts["field_sigma"][-1].ravel(), dense, rtol=1e-6)  # stored in float32
    # nees recomputed from the stored fields (the record keeps every sample's field up to 2 t_E)
    fillet = Fillet.on_grid(ts["x"], ts["y"], float(ts["L_s"]), float(ts["W_s"]))
    z = (ts["field_hat"][-1] - ts["field_true"][-1]) / ts["field_sigma"][-1]
    assert ts["nees"][-1] == pytest.approx(np.mean(z[fillet.mask] ** 2), rel=1e-5)


def test_metrics_count_the_truth_inside_two_sigma(run) -> None:
    """coverage from the stored series, by hand: the share of fillet cells x field samples in the window."""
    loop, _ = run
    ts = loop.timeseries()
    m = compute_metrics(ts)
    assert set(UNCERTAINTY_KEYS) <= set(m)
    fillet = Fillet.on_grid(ts["x"], ts["y"], float(ts["L_s"]), float(ts["W_s"]))
    tf = ts["t_field"]
    inside = np.abs(ts["field_hat"] - ts["field_true"]) <= 2.0 * ts["field_sigma"]
    for key, sel in (("coverage_2sigma_transient", tf <= 2.0 + 1e-9),
                     ("coverage_2sigma_steady", (tf >= 3.0 - 1e-9) & (tf <= 4.0 + 1e-9))):
        assert m[key] == pytest.approx(np.mean(inside[sel][:, fillet.mask]), abs=1e-12), key
    assert m["nis_mean"] == pytest.approx(np.nanmean(ts["nis"][ts["t"] >= 0.2 - 1e-9]))
    # a plausible bug: a sigma twice as large covers more
    wide = dict(ts, field_sigma=2.0 * ts["field_sigma"])
    assert compute_metrics(wide)["coverage_2sigma_steady"] >= m["coverage_2sigma_steady"]
    assert compute_metrics(wide)["nees_mean"] == pytest.approx(m["nees_mean"] / 4.0, rel=1e-5)


def test_stream_frame_and_opcua_carry_sigma_mean(run) -> None:
    _, snaps = run
    s = snaps[-1]
    frame = frame_dict(s, run_id="r", seq=1, wall_time=0.0, status="running")
    assert frame["sigma_mean"] == pytest.approx(s.sigma_mean) and frame["nis"] == pytest.approx(s.nis)
    assert np.asarray(frame["field_sigma"]).shape == s.field_hat.shape
    assert sample_values(s)["FieldSigmaMean"] == pytest.approx(s.sigma_mean)  # no longer BadNoData
    assert frame_values(frame)["FieldSigmaMean"] == pytest.approx(s.sigma_mean)



def test_dashboard_series_and_stored_snapshot_carry_the_uncertainty(run) -> None:
    """GET /api/runs/{id}/series (the dashboard's history: band and sigma map) and the 3D view's stored sample."""
    from backend.streaming.series import series_json
    from twin.runs.record import last_snapshot

    loop, _ = run
    ts = loop.timeseries()
    js = series_json(ts, max_points=10)
    assert len(js["sigma_mean"]) == len(js["t"]) <= 11
    np.testing.assert_allclose(np.asarray(js["field_sigma"]), ts["field_sigma"][-1], rtol=1e-6)
    snap = last_snapshot(ts)
    assert snap is not None and snap.field_sigma is not None
    assert snap.sigma_mean == pytest.approx(float(ts["sigma_mean"][-1]))
