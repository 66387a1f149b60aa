"""EKF covariance properties (hypothesis) and the measurement gate at its edges (paper eqs. 13-15).

Properties: after any prediction (eq. 15, float64 or the float32 product) and any update (eq. 13,
Joseph form), gated, missing or recovering, P stays exactly symmetric and positive definite, and
the update never increases the variance of any state (a measurement only adds information).

Gate edges (``ekf.innovation_gate``): a reading is used iff it is finite and
|nu_i| / sqrt(S_ii) <= gate.  With P = 0 the innovation covariance is S = R = r0 I exactly, so the
normalised innovation of a reading y_i is |y_i| / sqrt(r0): the numbers below sit exactly at,
just above and just below the gate.  The recovery rule (every working TC beyond the gate, at least
two working) is switched on and off at its conditions.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from twin.estimation.ekf import EKFState, ekf_update, process_noise, propagate_covariance


def _spd(draw, n, lo=0.1, hi=100.0):
    """A symmetric positive definite matrix with eigenvalues in [lo, hi] (random orthogonal basis)."""
    A = draw(arrays(float, (n, n), elements=st.floats(-1.0, 1.0)))
    Qm, _ = np.linalg.qr(A + 3.0 * np.eye(n))
    lam = draw(arrays(float, n, elements=st.floats(lo, hi)))
    P = (Qm * lam) @ Qm.T
    return 0.5 * (P + P.T)


@st.composite
def _filter_cases(draw):
    n = draw(st.integers(2, 8))
    p = draw(st.integers(1, 3))
    P = _spd(draw, n)
    C = draw(arrays(float, (p, n), elements=st.floats(0.0, 1.0)))
    C[np.arange(p), np.arange(p) % n] += 0.5  # rows like phi(xi)^T: non-negative, not all zero
    C /= C.sum(axis=1, keepdims=True)
    R = np.diag(draw(arrays(float, p, elements=st.floats(0.1, 10.0))))
    theta = draw(arrays(float, n, elements=st.floats(-500.0, 500.0)))
    # readings: plausible, far off (gated), missing (NaN, inf)
    y = C @ theta + draw(arrays(float, p, elements=st.floats(-20.0, 20.0)))
    kinds = draw(st.lists(st.sampled_from(["ok", "ok", "far", "nan", "inf"]), min_size=p, max_size=p))
    for i, k in enumerate(kinds):
        y[i] = {"ok": y[i], "far": y[i] + 1e4, "nan": np.nan, "inf": np.inf}[k]
    gate = draw(st.sampled_from([np.inf, 6.0, 3.0, 1.0, 0.2]))
    Phi = np.eye(n) + draw(arrays(float, (n, n), elements=st.floats(-0.05, 0.05)))
    M = _spd(draw, n, 0.5, 2.0)  # a mass-matrix-like pattern for Q (sign(M) of eq. section 3.2)
    q0, q1 = draw(st.floats(1e-3, 1.0)), draw(st.floats(0.0, 5.0))
    return P, C, R, theta, y, gate, Phi, process_noise(M, q0, q1)


def _assert_spd(P: np.ndarray) -> None:
    np.testing.assert_array_equal(P, P.T)  # exactly: both steps symmetrise
    assert np.linalg.eigvalsh(P).min() > 0.0


@given(_filter_cases())
def test_covariance_stays_symmetric_positive_definite(case) -> None:
    P, C, R, theta, y, gate, Phi, Q = case
    for dtype in (np.float64, np.float32):  # ekf.covariance_precision "double" / "single"
        P_pred = propagate_covariance(Phi.astype(dtype), P, Q)
        _assert_spd(P_pred)
        # the prediction adds Q (PSD) to Phi P Phi^T: it never shrinks below the propagated covariance
        assert np.linalg.eigvalsh(P_pred - Phi @ P @ Phi.T).min() > -1e-5 * np.abs(P_pred).max()
        st_new, info = ekf_update(EKFState(theta, P_pred), y, C, R, gate)
        _assert_spd(st_new.P)
        finite = np.isfinite(y)
        recovered = finite.sum() >= 2 and bool((info.normalized[finite] > gate).all())
        if not info.used.any():
            np.testing.assert_array_equal(st_new.P, P_pred)
        elif not recovered:
            # without the recovery inflation a measurement can only reduce each variance
            assert (np.diag(st_new.P) <= np.diag(P_pred) * (1 + 1e-9) + 1e-9).all()


@given(_filter_cases())
def test_used_readings_are_exactly_the_finite_ones_inside_the_gate(case) -> None:
    P, C, R, theta, y, gate, _, _ = case
    _, info = ekf_update(EKFState(theta, P), y, C, R, gate)
    finite = np.isfinite(y)
    S = C @ P @ C.T + R
    normalized = np.abs(y - C @ theta) / np.sqrt(np.diag(S))
    inside = finite & (normalized <= gate)
    if finite.sum() >= 2 and not inside.any():
        expected = finite  # every working TC beyond the gate: the estimate is taken to be wrong
    else:
        expected = inside
    np.testing.assert_array_equal(info.used, expected)
    assert info.reasons == tuple("" if u else ("missing" if not f else "gated")
                                 for u, f in zip(expected, finite, strict=True))


# ------------------------------------------------------------------ the gate at its edges
R0 = 4.0  # K^2: sqrt(S_ii) = 2 K exactly when P = 0
GATE = 3.0  # sigma: the threshold innovation is 6 K
C3 = np.eye(3)
R3 = R0 * np.eye(3)


def _update(y, gate=GATE, P=None):
    state = EKFState(np.zeros(3), np.zeros((3, 3)) if P is None else P)
    return ekf_update(state, np.asarray(y, float), C3, R3, gate)


@pytest.mark.parametrize(
    ("y1", "used"),
    [(6.0, True), (-6.0, True), (np.nextafter(6.0, 7.0), False), (np.nextafter(6.0, 5.0), True), (6.1, False),
     (5.9, True)],
    ids=["at", "at-negative", "one-ulp-above", "one-ulp-below", "above", "below"],
)
def test_a_reading_at_the_gate_is_used_and_beyond_it_left_out(y1, used) -> None:
    _, info = _update([y1, 0.5, -0.5])  # two good readings keep the recovery rule off
    np.testing.assert_array_equal(info.innovation, [y1, 0.5, -0.5])  # y - C theta with theta = 0
    assert info.normalized[0] == pytest.approx(abs(y1) / 2.0, rel=1e-15)
    assert info.used.tolist() == [used, True, True]
    assert info.reasons[0] == ("" if used else "gated")


def test_gate_off_uses_every_finite_reading() -> None:
    _, info = _update([1e6, -1e6, np.nan], gate=np.inf)
    assert info.used.tolist() == [True, True, False] and info.reasons == ("", "", "missing")


def test_inf_reading_is_missing_not_gated() -> None:
    _, info = _update([np.inf, 0.0, 0.0])
    assert info.used.tolist() == [False, True, True] and info.reasons[0] == "missing"


def test_recovery_needs_every_working_reading_beyond_the_gate() -> None:
    P = np.eye(3)  # S_ii = 1 + 4 = 5 K^2
    # one of three within the gate: no recovery, the two others are just left out
    _, info = _update([100.0, 100.0, 1.0], P=P)
    assert info.used.tolist() == [False, False, True] and info.reasons == ("gated", "gated", "")
    # all three beyond: recovery, all used
    _, info = _update([100.0, 200.0, 300.0], P=P)
    assert info.used.all() and info.reasons == ("", "", "")


@pytest.mark.parametrize(("y", "recovers"), [([100.0, 200.0, np.nan], True), ([100.0, np.nan, np.nan], False)],
                         ids=["two-working", "one-working"])
def test_recovery_needs_at_least_two_working_readings(y, recovers) -> None:
    P = np.eye(3)
    before = EKFState(np.zeros(3), P)
    after, info = ekf_update(before, np.asarray(y, float), C3, R3, GATE)
    finite = np.isfinite(y)
    if recovers:
        assert info.used.tolist() == finite.tolist()
        # P inflated so that the closest reading (100 K, S = 5 K^2) sits at the gate:
        # scale = (100 / sqrt(5) / 3)^2; the update is then the textbook one with scale * P
        scale = (100.0 / np.sqrt(5.0) / GATE) ** 2
        keep = np.flatnonzero(finite)
        Ps = scale * P
        Cu, Ru = C3[keep], R3[np.ix_(keep, keep)]
        K = Ps @ Cu.T @ np.linalg.inv(Cu @ Ps @ Cu.T + Ru)
        np.testing.assert_allclose(after.theta, K @ np.asarray(y)[keep], rtol=1e-12)
        np.testing.assert_allclose(after.P, (np.eye(3) - K @ Cu) @ Ps, rtol=1e-12, atol=1e-12)
    else:
        # one sensor against the estimate: the sensor is left out, the estimate kept
        assert not info.used.any() and info.reasons == ("gated", "missing", "missing")
        np.testing.assert_array_equal(after.theta, before.theta)
        np.testing.assert_array_equal(after.P, before.P)


# ------------------------------------------------------------------ prediction and the Estimator
class _Bilinear:
    """theta+ = theta + 0.1 (-theta^3 / 1e6 + u0 theta): a Jacobian that depends on theta and on u."""

    def step(self, theta, u):
        return theta + 0.1 * (-(theta**3) / 1e6 + u[0] * theta)

    def jac_theta(self, theta, u):
        return np.diag(1.0 + 0.1 * (-3.0 * theta**2 / 1e6 + u[0]))


def test_prediction_linearises_at_the_estimate_and_the_input() -> None:
    """Eqs. (14)-(16) by hand on a two-state model: Phi = diag(1 + 0.1 (-3 theta^2 / 1e6 + u))."""
    from twin.estimation.ekf import ekf_predict

    theta, u = np.array([100.0, 200.0]), np.array([-0.5])
    P, Q = np.array([[4.0, 1.0], [1.0, 9.0]]), 0.25 * np.eye(2)
    out = ekf_predict(_Bilinear(), EKFState(theta, P), u, Q)
    phi = np.array([1 + 0.1 * (-0.03 - 0.5), 1 + 0.1 * (-0.12 - 0.5)])  # 0.947, 0.938
    np.testing.assert_allclose(out.theta, theta + 0.1 * (-(theta**3) / 1e6 - 0.5 * theta), rtol=1e-15)
    np.testing.assert_allclose(out.P, np.outer(phi, phi) * P + Q, rtol=1e-14)


def test_gain_falls_back_to_the_general_solver_when_cholesky_fails() -> None:
    from twin.estimation.ekf import _gain

    S = np.array([[1.0, 2.0], [2.0, 1.0]])  # symmetric, indefinite: LAPACK's Cholesky refuses it
    PCt = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    # K = P C^T S^-1 with S^-1 = [[-1, 2], [2, -1]] / 3 (by hand)
    np.testing.assert_allclose(_gain(S, PCt), PCt @ np.array([[-1.0, 2.0], [2.0, -1.0]]) / 3.0, rtol=1e-14)
    S_pd = np.array([[2.0, 1.0], [1.0, 2.0]])  # the normal path: S^-1 = [[2, -1], [-1, 2]] / 3
    np.testing.assert_allclose(_gain(S_pd, PCt), PCt @ np.array([[2.0, -1.0], [-1.0, 2.0]]) / 3.0, rtol=1e-14)


@pytest.fixture(scope="module")
def furnace_model(small_radiation):
    from twin.config import small_config
    from twin.model.discrete import discrete_model

    return small_config(), discrete_model(small_config(), small_radiation, None)


def test_estimator_steps_in_the_papers_order(furnace_model) -> None:
    """step(y, u_prev): update only at the first sample, then predict with the last input and update (13, 14)."""
    from twin.estimation.ekf import Estimator, ekf_predict

    cfg, model = furnace_model
    theta0 = np.linspace(880.0, 920.0, model.n)  # a non-uniform initial estimate is kept as given
    est = Estimator(model, cfg, theta0)
    np.testing.assert_array_equal(est.state.theta, theta0)
    np.testing.assert_array_equal(est.state.P, cfg.ekf.p0 * np.eye(model.n))
    C, R, gate = est.C, est.R, cfg.ekf.innovation_gate
    y1, y2, u = np.array([905.0, 898.0, 910.0]), np.array([912.0, 903.0, 915.0]), np.full(model.m, 0.4)
    first = est.step(y1, u)
    expected, _ = ekf_update(EKFState(theta0, cfg.ekf.p0 * np.eye(model.n)), y1, C, R, gate)
    np.testing.assert_allclose(first.theta, expected.theta, rtol=1e-12)
    second = est.step(y2, u)
    # Phi in float32 by default (ekf.covariance_precision): P within float32 rounding of the exact filter
    expected, _ = ekf_update(ekf_predict(model, expected, u, est.Q), y2, C, R, gate)
    np.testing.assert_allclose(second.theta, expected.theta, rtol=1e-6)
    np.testing.assert_allclose(second.P, expected.P, rtol=1e-4, atol=1e-4 * np.abs(expected.P).max())
    # the estimate at any point is the FE interpolation of the nodes (eq. 7)
    pts = np.array([[0.1, 0.05], [0.2, 0.1]])
    np.testing.assert_allclose(est.estimate_at(pts), model.fe.phi(pts) @ est.state.theta, rtol=1e-15)


@pytest.mark.parametrize(("precision", "dtype"), [("single", np.float32), ("double", np.float64)])
def test_covariance_precision_chooses_the_product(furnace_model, precision, dtype) -> None:
    """ekf.covariance_precision: Phi P Phi^T (15) formed in float32 ("single") or float64 ("double")."""
    from twin.estimation.ekf import Estimator, propagate_covariance

    cfg, model = furnace_model
    cfg = cfg.with_overrides({"ekf.covariance_precision": precision})
    est = Estimator(model, cfg, 900.0)
    u = np.full(model.m, 0.4)
    theta, P = est.state.theta.copy(), est.state.P.copy()
    est.predict(u)
    np.testing.assert_array_equal(est.state.P, propagate_covariance(model.jac_theta(theta, u).astype(dtype), P, est.Q))
    np.testing.assert_array_equal(est.state.theta, model.step(theta, u))
