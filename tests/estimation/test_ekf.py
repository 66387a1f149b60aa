"""EKF (paper eqs. 13-16) against an independently written linear Kalman filter, and faulty TCs."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import pytest

from twin.estimation.ekf import EKFState, ekf_predict, ekf_update, process_noise


class LinearModel:
    """theta_{j+1} = A theta_j + B u_j: the EKF must reduce to the linear Kalman filter."""

    def __init__(self, A: np.ndarray, B: np.ndarray) -> None:
        self.A, self.B = A, B

    def step(self, theta, u):
        return self.A @ theta + self.B @ u

    def jac_theta(self, theta, u):
        return self.A


def _reference_kf(A, B, C, Q, R, x0, P0, ys, us):
    """Textbook KF (Simon 2006, eqs. 5.19): K = P C'(C P C' + R)^-1, P+ = (I - K C) P."""
    x, P = x0.copy(), P0.copy()
    out = []
    for j, y in enumerate(ys):
        if j > 0:
            x = A @ x + B @ us[j - 1]
            P = A @ P @ A.T + Q
        K = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
        x = x + K @ (y - C @ x)
        P = (np.eye(len(x)) - K @ C) @ P
        out.append((x.copy(), P.copy()))
    return out


@dataclass
class SimpleSystem:
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    ys: np.ndarray
    us: np.ndarray


@pytest.fixture
def system() -> SimpleSystem:
    rng = np.random.default_rng(7)
    n, m, p = 8, 2, 3
    A = np.eye(n) + 0.05 * rng.normal(size=(n, n))
    A *= 0.98 / max(abs(np.linalg.eigvals(A)))
    B = rng.normal(size=(n, m))
    C = rng.uniform(0, 1, size=(p, n))
    C /= C.sum(axis=1, keepdims=True)  # rows like phi(xi)^T: non-negative, summing to 1
    M = np.diag(np.full(n, 4.0)) + np.diag(np.ones(n - 1), 1) + np.diag(np.ones(n - 1), -1)
    Q = process_noise(M, 1e-2, 2.0)
    R = 0.5 * np.eye(p)
    x_true = rng.normal(size=n) * 10
    us = rng.normal(size=(40, m))
    ys = []
    for u in us:
        ys.append(C @ x_true + rng.normal(size=p) * 0.7)
        x_true = A @ x_true + B @ u + rng.normal(size=n) * 0.1
    return SimpleSystem(A, B, C, Q, R, np.zeros(n), 25.0 * np.eye(n), np.array(ys), us)


def _run_ekf(sy, ys, gate=np.inf):
    model = LinearModel(sy.A, sy.B)
    st = EKFState(sy.x0.copy(), sy.P0.copy())
    out = []
    for j, y in enumerate(ys):
        if j > 0:
            st = ekf_predict(model, st, sy.us[j - 1], sy.Q)
        st, info = ekf_update(st, y, sy.C, sy.R, gate)
        out.append((st, info))
    return out


def test_ekf_on_a_linear_system_is_the_kalman_filter(system) -> None:
    sy = system
    ref = _reference_kf(sy.A, sy.B, sy.C, sy.Q, sy.R, sy.x0, sy.P0, sy.ys, sy.us)
    got = _run_ekf(sy, sy.ys)
    for (x_ref, P_ref), (st, _) in zip(ref, got, strict=True):
        # the brief's bound; Joseph vs (I - K C) P differ only by rounding (~1e-13 here)
        np.testing.assert_allclose(st.theta, x_ref, atol=1e-9)
        np.testing.assert_allclose(st.P, P_ref, atol=1e-9)


def test_missing_reading_equals_update_without_that_sensor(system, caplog) -> None:
    sy = system
    st = EKFState(sy.x0.copy(), sy.P0.copy())
    y = sy.ys[0].copy()
    y[1] = np.nan
    with caplog.at_level(logging.DEBUG, logger="twin.estimation.ekf"):
        got, info = ekf_update(st, y, sy.C, sy.R, gate=6.0)
    # said at debug level: a missing reading is the loop's to report, once per outage (30 warnings a second before)
    assert [(r.levelname, "TC2" in r.message and "missing" in r.message) for r in caplog.records] == [("DEBUG", True)]
    assert info.used.tolist() == [True, False, True]
    keep = [0, 2]
    ref = _reference_kf(sy.A, sy.B, sy.C[keep], sy.Q, sy.R[np.ix_(keep, keep)], sy.x0, sy.P0, [y[keep]], sy.us)
    np.testing.assert_allclose(got.theta, ref[0][0], atol=1e-9)
    np.testing.assert_allclose(got.P, ref[0][1], atol=1e-9)


def test_absurd_reading_is_gated_and_the_filter_keeps_going(system, caplog) -> None:
    sy = system
    ys = sy.ys.copy()
    ys[10:20, 2] += 400.0  # TC3 jumps by 400 K (broken wire / short): hundreds of sigma
    ys[25, :] = np.nan  # all three drop out for one sample
    with caplog.at_level(logging.WARNING, logger="twin.estimation.ekf"):
        got = _run_ekf(sy, ys, gate=6.0)
    assert "gated" in caplog.text
    for j in range(10, 20):
        assert got[j][1].reasons[2] == "gated"
    assert got[25][1].used.sum() == 0
    clean = _run_ekf(sy, sy.ys, gate=6.0)
    assert all(info.used.all() for _, info in clean)  # a 6-sigma gate never trips on clean data here
    # estimate after the fault: the gated run lost only TC3's information over 10 samples, so it stays
    # within a few noise standard deviations (0.7) of the clean run, not 400 K away
    assert np.max(np.abs(got[-1][0].theta - clean[-1][0].theta)) < 5.0
    for st, _ in got:
        np.testing.assert_array_equal(st.P, st.P.T)
        assert np.linalg.eigvalsh(st.P).min() > 0


def test_process_noise_worked_example() -> None:
    """Q = q0 (q1 sign(M) + 1 1^T)^2 of section 3.2 worked by hand for a two-element 1D mesh.

    Linear elements of length h on nodes 0, 1, 2: M = h/6 [[2, 1, 0], [1, 4, 1], [0, 1, 2]], so
    sign(M) = [[1, 1, 0], [1, 1, 1], [0, 1, 1]].  With q1 = 2: S = 2 sign(M) + 1 1^T =
    [[3, 3, 1], [3, 3, 3], [1, 3, 3]] and the matrix square (rows times columns, by hand)
    S^2 = [[19, 21, 15], [21, 27, 21], [15, 21, 19]]; with q0 = 0.5, Q = S^2 / 2.
    (The element-wise square would give [[9, 9, 1], ...]: a different, wrong reading.)
    """
    M = 0.01 / 6 * np.array([[2.0, 1.0, 0.0], [1.0, 4.0, 1.0], [0.0, 1.0, 2.0]])
    Q = process_noise(M, 0.5, 2.0)
    np.testing.assert_array_equal(Q, [[9.5, 10.5, 7.5], [10.5, 13.5, 10.5], [7.5, 10.5, 9.5]])


def test_process_noise_of_the_fe_mesh_in_closed_form(small_radiation) -> None:
    """The Estimator's Q on the real FE mass matrix against the equation expanded by neighbour counts.

    With A = sign(M) (nodes sharing an element, diagonal included; M >= 0 entry-wise) and
    d_i = sum_k A_ik the number of such neighbours of node i, (q1 A + 1 1^T)^2 =
    q1^2 A^2 + q1 (d 1^T + 1 d^T) + n 1 1^T.  (A^2)_ij counts the nodes adjacent to both i and j.
    """
    from twin.config import small_config
    from twin.estimation.ekf import Estimator
    from twin.model.discrete import discrete_model

    cfg = small_config()
    est = Estimator(discrete_model(cfg, small_radiation, None), cfg, 900.0)
    M = est.model.fe.M
    A = (M != 0).astype(float)
    d = A.sum(axis=1)
    n = len(d)
    q0, q1 = cfg.ekf.q0, cfg.ekf.q1
    expected = q0 * (q1**2 * (A @ A) + q1 * (d[:, None] + d[None, :]) + n)
    np.testing.assert_allclose(est.Q, expected, rtol=1e-12)
    # bilinear elements: a corner node touches 4 nodes, an interior one 9 (a 3 x 3 stencil)
    nx = len(cfg.fe.x_nodes)
    assert d[0] == 4 and d[nx + 1] == 9
    np.testing.assert_array_equal(est.R, cfg.ekf.r0 * np.eye(3))  # R = r0 I (section 3.2)
    np.testing.assert_array_equal(est.state.P, cfg.ekf.p0 * np.eye(n))  # P_0 = p0 I


def test_all_readings_beyond_the_gate_means_the_estimate_is_wrong(system, caplog) -> None:
    """Three sensors failing at once is less likely than a wrong estimate: inflate P and use them."""
    sy = system
    P = 0.01 * np.eye(len(sy.x0))  # over-confident
    st = EKFState(sy.x0 + 200.0, P)  # and 200 K off
    y = sy.C @ sy.x0
    with caplog.at_level(logging.WARNING, logger="twin.estimation.ekf"):
        got, info = ekf_update(st, y, sy.C, sy.R, gate=6.0)
    assert "beyond the gate" in caplog.text
    assert info.used.all()
    # oracle: the textbook update with P scaled so that the closest reading sits at the gate
    nu = y - sy.C @ st.theta
    s = (np.min(np.abs(nu) / np.sqrt(np.diag(sy.C @ P @ sy.C.T + sy.R))) / 6.0) ** 2
    ref = _reference_kf(sy.A, sy.B, sy.C, sy.Q, sy.R, st.theta, s * P, [y], sy.us)
    np.testing.assert_allclose(got.theta, ref[0][0], atol=1e-9)
    np.testing.assert_allclose(got.P, ref[0][1], atol=1e-9)
    # the estimate moved most of the way back (measured: from 200 K to at most 15 K off at the TCs)
    assert np.max(np.abs(sy.C @ got.theta - y)) < 200.0 / 4
    # a single gated reading among good ones is still just left out
    y1 = y.copy()
    y1[0] += 1e4
    good = EKFState(sy.x0.copy(), 25.0 * np.eye(len(sy.x0)))
    _, info1 = ekf_update(good, y1, sy.C, sy.R, gate=6.0)
    assert info1.used.tolist() == [False, True, True]


def test_jacobian_is_reused_until_a_node_moves_more_than_the_tolerance(small_radiation) -> None:
    """Phi (16) is cached by the Estimator: re-evaluated after a move > ekf.jacobian_tolerance or a model switch."""
    from twin.config import small_config
    from twin.estimation.ekf import Estimator
    from twin.model.discrete import discrete_model

    cfg = small_config()
    tol = cfg.ekf.jacobian_tolerance
    model = discrete_model(cfg, small_radiation, None)
    calls: list[np.ndarray] = []

    class Counting:
        def __init__(self, inner):
            self.inner = inner

        def __getattr__(self, name):
            return getattr(self.inner, name)

        def jac_theta(self, theta, u):
            calls.append(np.array(theta))
            return self.inner.jac_theta(theta, u)

    counting = Counting(model)
    est = Estimator(counting, cfg, 900.0)
    u = np.full(model.m, 0.3)
    theta0, P0 = est.state.theta.copy(), est.state.P.copy()

    def predict_at(offset: float) -> None:
        est.state = EKFState(theta0 + offset, P0)
        est.predict(u)

    predict_at(0.0)
    predict_at(0.9 * tol)
    predict_at(tol)  # exactly at the tolerance (2 K: 900 + 2 is exact in floating point) still counts as within
    assert len(calls) == 1  # within the tolerance: the cached Phi is used
    predict_at(1.1 * tol)
    assert len(calls) == 2 and np.allclose(calls[-1], theta0 + 1.1 * tol)
    est.set_model(Counting(model))  # e.g. oscillation toggled: a new model object
    predict_at(1.1 * tol)
    assert len(calls) == 3
