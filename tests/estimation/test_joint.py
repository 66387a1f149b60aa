"""The joint (calibrating) and position-aware estimator (twin.estimation.joint, twin.model.parametric).

Oracles: the paper's EKF (twin.estimation.ekf.Estimator) for the configuration without extensions;
central finite differences for the Jacobians in theta (eq. 16) and in the parameters; a rebuild of the
net-radiation matrices at the changed emissivity for the linearised emissivity terms.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.estimation.ekf import Estimator
from twin.estimation.joint import JointEstimator
from twin.model.discrete import discrete_model
from twin.model.parametric import ParametricModel
from twin.model.tables import Parameters, model_tables
from twin.physics.motion import hat_weights
from twin.scenario import OscillationSpec

CFG = small_config()
OSC = OscillationSpec(enabled=True, amplitude=0.02, period=4.0)


@pytest.fixture(scope="module")
def tables(small_radiation):
    return model_tables(CFG, small_radiation)


@pytest.mark.parametrize("oscillation", [None, OSC], ids=["fixed", "oscillating"])
def test_without_extensions_it_is_the_papers_filter(small_radiation, tables, oscillation) -> None:
    paper = Estimator(discrete_model(CFG, small_radiation, oscillation, tables=tables), CFG, 300.0)
    joint = JointEstimator(ParametricModel(tables, oscillation), CFG, 300.0)
    truth = np.full(tables.n, 300.0)
    u = np.full(6, 0.7)
    rng = np.random.default_rng(5)
    model = paper.model
    for j in range(200):
        y = paper.C @ truth + rng.normal(size=3)
        paper.update(y)
        joint.update(y)
        paper.predict(u)
        joint.predict(u, 0.013 * np.sin(j))  # the averaged model ignores the position
        truth = model.step(truth, u)
    # the same algebra in a different order of summation: round-off only (K, K^2)
    np.testing.assert_allclose(joint.state.theta, paper.state.theta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(joint.state.P, paper.state.P, rtol=0, atol=1e-9 * np.abs(paper.state.P).max())


def test_position_aware_equals_averaged_for_a_fixed_specimen(tables) -> None:
    aware = ParametricModel(tables, None, motion="position_aware", calibrated=("lamp_efficiency", "emissivity"))
    averaged = ParametricModel(tables, None, motion="averaged", calibrated=("lamp_efficiency", "emissivity"))
    theta = np.linspace(400.0, 1100.0, tables.n)
    u, p = np.full(6, 0.6), Parameters(lamp_efficiency=-0.08, emissivity=-0.03)
    np.testing.assert_array_equal(aware.step(theta, u, 0.0, p), averaged.step(theta, u, 0.0, p))
    np.testing.assert_array_equal(aware.jac_p(theta, u, 0.0, p), averaged.jac_p(theta, u, 0.0, p))
    # and estimators on them agree sample by sample on the same readings
    a, b = JointEstimator(aware, CFG, 300.0), JointEstimator(averaged, CFG, 300.0)
    for _ in range(50):
        y = np.array([500.0, 495.0, 502.0])
        a.update(y), b.update(y)
        a.predict(u, 0.0), b.predict(u, 0.0)
    np.testing.assert_allclose(a.state.theta, b.state.theta, rtol=0, atol=1e-12)


def test_position_aware_model_is_the_table_at_eta(small_radiation, tables) -> None:
    """At a table node eta_k the position-aware model is the model built from P1(eta_k), P2(eta_k) alone."""
    aware = ParametricModel(tables, OSC, motion="position_aware")
    k = len(tables.eta_nodes) // 2 + 1
    eta = float(tables.eta_nodes[k])
    L, A, B, c = tables.terms(hat_weights(tables.eta_nodes, eta))
    theta = np.linspace(500.0, 1000.0, tables.n)
    T4 = tables.fe.field_on_cells(theta).ravel() ** 4
    expected = theta + tables.t_s * (L @ theta + A @ T4 + B @ np.full(6, 0.5) + c)
    np.testing.assert_allclose(aware.step(theta, np.full(6, 0.5), eta), expected, rtol=1e-13)


@pytest.mark.parametrize("heat_capacity", ["constant", "temperature"])
def test_jacobians_against_finite_differences(tables, heat_capacity) -> None:
    model = ParametricModel(tables, OSC, motion="position_aware",
                            calibrated=("lamp_efficiency", "emissivity", "convection"), heat_capacity=heat_capacity)
    # nodes between 450 and 1100 K: through the Curie peak of c_p (1042 K), away from the table's kinks
    theta = np.linspace(450.0, 1100.0, tables.n) + 0.37
    u, eta, p = np.full(6, 0.55), 0.0131, Parameters(0.05, -0.03, 0.2)
    J = model.jac_theta(theta, u, eta, p)
    h = 1e-3  # K: the T^4 term's truncation error ~ h^2 * 12 T^2 * |A| ~ 1e-10
    fd = np.column_stack([(model.step(theta + h * e, u, eta, p) - model.step(theta - h * e, u, eta, p)) / (2 * h)
                          for e in np.eye(tables.n)])
    np.testing.assert_allclose(J, fd, rtol=0, atol=1e-8 if heat_capacity == "constant" else 1e-7)
    Jp = model.jac_p(theta, u, eta, p)
    for i in range(3):
        dp = np.zeros(3)
        dp[i] = 1e-6  # F is linear in each parameter: the difference is exact up to round-off
        up = model.step(theta, u, eta, Parameters.from_array(p.as_array() + dp))
        down = model.step(theta, u, eta, Parameters.from_array(p.as_array() - dp))
        np.testing.assert_allclose(Jp[:, i], (up - down) / 2e-6, rtol=0, atol=1e-6 * np.abs(Jp[:, i]).max())


def test_linearised_emissivity_against_a_rebuilt_model(small_radiation, tables) -> None:
    eps = CFG.specimen.emissivity
    w = hat_weights(tables.eta_nodes, 0.0)
    exact = model_tables(CFG, small_radiation.with_specimen_emissivity(0.95 * eps), tables.fe).terms(w)
    nominal = tables.terms(w)
    linear = tables.terms(w, Parameters(emissivity=-0.05))
    for name, ex, lin, nom in zip("LABc", exact, linear, nominal, strict=True):
        change = np.abs(ex - nom).max()
        # second-order remainder of a 5 % step: measured 2e-4 (A), 4e-3 (c), 1.6e-2 (B) of the change
        assert np.abs(lin - ex).max() <= 0.03 * change + 1e-15, name


def test_parameters_are_kept_within_bounds(tables) -> None:
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency",))
    est = JointEstimator(model, CFG, 1000.0)
    lo, hi = CFG.calibration.bounds.lamp_efficiency
    for _ in range(100):  # readings far above what any lamp efficiency can explain
        est.update(np.full(3, 1250.0))
        est.predict(np.zeros(6))
    assert lo <= est.parameters.lamp_efficiency <= hi
    assert est.calibration()["lamp_efficiency"]["sigma"] > 0.0


def test_consider_states_keep_their_value_and_the_joseph_covariance() -> None:
    """ekf_update(consider=k): the last k states are not moved by the readings (Schmidt-Kalman); oracle: the
    Joseph form (I - K C) P (I - K C)^T + K R K^T written out with the optimal gain's last k rows set to 0."""
    from twin.estimation.ekf import EKFState, ekf_update

    rng = np.random.default_rng(5)
    A = rng.normal(size=(5, 5))
    P = A @ A.T + 5 * np.eye(5)
    C = rng.normal(size=(2, 5))
    R = np.diag([0.5, 2.0])
    x = rng.normal(size=5)
    y = C @ x + np.array([1.0, -2.0])
    got, _ = ekf_update(EKFState(x, P), y, C, R, np.inf, consider=2)
    K = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    K[-2:] = 0.0
    I_KC = np.eye(5) - K @ C
    assert np.allclose(got.theta, x + K @ (y - C @ x), atol=1e-12)
    assert np.array_equal(got.theta[-2:], x[-2:])
    assert np.allclose(got.P, I_KC @ P @ I_KC.T + K @ R @ K.T, atol=1e-10)
    # the considered uncertainty still acts: the first states' gain is the optimal one's, not that of a filter
    # that knew the last two exactly
    full, _ = ekf_update(EKFState(x, P), y, C, R, np.inf)
    assert np.allclose(full.theta[:3], got.theta[:3], atol=1e-12)


@pytest.mark.parametrize("heat_capacity", ["constant", "temperature"])
def test_the_kept_jacobian_follows_the_position(tables, heat_capacity) -> None:
    """Phi (16) is assembled from per-position pieces and kept while nothing changed (issue 21); a move of the
    specimen within one table interval changes only the weights, and Phi must follow them: against the exact
    Jacobian of the model at the new position (float32, so 1e-5 of its largest entry)."""
    model = ParametricModel(tables, OSC, motion="position_aware", heat_capacity=heat_capacity)
    est = JointEstimator(model, CFG, 300.0)
    theta = np.linspace(500.0, 900.0, tables.n)
    u, p = np.full(6, 0.6), Parameters()
    eta = np.asarray(tables.eta_nodes, float)
    for where in (0.2, 0.7, 0.7, 0.2):  # two table positions, other weights, kept (a hit), then back
        at = float(eta[1] + where * (eta[2] - eta[1]))
        Phi = est._jacobian(model.evaluate(theta, u, at, p), at, p)
        exact = model.jac_theta(theta, u, at, p)
        np.testing.assert_allclose(Phi, exact, rtol=0, atol=1e-5 * np.abs(exact).max())
