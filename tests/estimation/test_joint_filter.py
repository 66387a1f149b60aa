"""The joint estimator's own bookkeeping (twin.estimation.joint.JointEstimator): its prior, random walk,
bounds, consider mode, reported covariance and the kept Jacobian's cache keys.

Oracles: the config's numbers (prior sigma, random walk, bounds, t_s); the model's own exact Jacobians
(``ParametricModel.jac_theta`` / ``jac_p``, checked against finite differences in test_joint.py);
:func:`twin.estimation.ekf.ekf_update` and :func:`twin.estimation.ekf.process_noise` (tested in
test_ekf.py) for what the estimator must hand them; the Joseph form written out.  Double precision
(``ekf.covariance_precision = "double"``) where an exact comparison is meant; small_config's
``single`` where the dtype itself is the point.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.estimation.ekf import EKFState, ekf_update, process_noise
from twin.estimation.joint import PARAMETER_TOLERANCE, JointEstimator
from twin.model.parametric import ParametricModel
from twin.model.tables import Parameters, model_tables
from twin.scenario import OscillationSpec

CFG = small_config()
DOUBLE = CFG.with_overrides({"ekf.covariance_precision": "double"})
OSC = OscillationSpec(enabled=True, amplitude=0.02, period=4.0)
ALL3 = ("lamp_efficiency", "emissivity", "convection")


@pytest.fixture(scope="module")
def tables(small_radiation):
    return model_tables(CFG, small_radiation)


def test_initial_estimate_is_theta0_and_the_prior(tables) -> None:
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency", "emissivity"))
    theta0 = np.linspace(300.0, 400.0, tables.n)  # a field, not a scalar
    p0 = Parameters(lamp_efficiency=0.02, emissivity=-0.01, convection=0.3)
    est = JointEstimator(model, DOUBLE, theta0, p0)
    np.testing.assert_array_equal(est.state.theta, theta0)
    # the calibrated parameters start at p0 with the config's prior sigma; the others stay at p0
    assert est.parameters == p0
    np.testing.assert_array_equal(est.parameter_sigma, [CFG.calibration.prior_sigma.lamp_efficiency,
                                                        CFG.calibration.prior_sigma.emissivity])
    np.testing.assert_array_equal(est.state.P, CFG.ekf.p0 * np.eye(tables.n))
    assert est.cfg is DOUBLE
    # a scalar theta0 is a uniform field
    np.testing.assert_array_equal(JointEstimator(model, DOUBLE, 350).state.theta, np.full(tables.n, 350.0))


def test_parameter_variance_grows_by_the_random_walk(tables) -> None:
    """Without readings each predict adds r_p^2 t_s to a parameter's variance (Q_x of eq. 15): its rows of
    Phi_x are [0 I], so nothing else reaches that block."""
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency", "emissivity"))
    est = JointEstimator(model, DOUBLE, 800.0)
    before = est.parameter_sigma**2
    for _ in range(20):
        est.predict(np.full(6, 0.5))
    rw = np.array([CFG.calibration.random_walk.lamp_efficiency, CFG.calibration.random_walk.emissivity])
    np.testing.assert_allclose(est.parameter_sigma**2 - before, 20 * rw**2 * CFG.sampling.t_s, rtol=1e-9)


@pytest.mark.parametrize("reading", [1400.0, 300.0], ids=["far above", "far below"])
def test_parameters_are_held_at_their_bounds(tables, reading) -> None:
    """Readings no parameter value can explain push the estimates out; after every update each is within its
    own bounds (the config's: lamp efficiency -0.5 .. 0.5, emissivity -0.3 .. 0.1), and the bound is reached
    (measured on this run: lamp efficiency at 0.5 and emissivity at -0.3 far above, lamp efficiency at -0.5
    far below)."""
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency", "emissivity"))
    est = JointEstimator(model, DOUBLE, 800.0)
    seen = []
    for _ in range(60):
        est.update(np.full(3, reading))
        seen.append((est.parameters.lamp_efficiency, est.parameters.emissivity))
        est.predict(np.full(6, 0.5))
    lamp, emis = np.array(seen).T
    b = CFG.calibration.bounds
    assert (b.lamp_efficiency, b.emissivity) == ((-0.5, 0.5), (-0.3, 0.1))
    assert lamp.min() >= -0.5 and lamp.max() <= 0.5 and emis.min() >= -0.3 and emis.max() <= 0.1
    if reading > 800.0:
        assert lamp.max() == 0.5 and emis.min() == -0.3
    else:
        assert lamp.min() == -0.5


def test_parameters_within_their_bounds_are_not_moved_to_them(tables) -> None:
    """Readings of the nominal model itself (noise-free): the estimates stay near 0, inside the bounds."""
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency", "emissivity"))
    est = JointEstimator(model, DOUBLE, 800.0)
    truth = np.full(tables.n, 800.0)
    u = np.full(6, 0.5)
    for _ in range(60):
        est.update(est.C[:, :tables.n] @ truth)
        est.predict(u)
        truth = model.step(truth, u)
    assert abs(est.parameters.lamp_efficiency) < 1e-3 and abs(est.parameters.emissivity) < 1e-3


def test_learn_false_keeps_the_parameters_as_consider_states(tables) -> None:
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency", "emissivity"))
    y = np.array([820.0, 815.0, 830.0])
    a, b = JointEstimator(model, DOUBLE, 800.0), JointEstimator(model, DOUBLE, 800.0)
    for est in (a, b):
        est.predict(np.full(6, 0.5))
    prior = EKFState(np.concatenate([a.state.theta, [0.0, 0.0]]), a._x.P.copy())
    # learn=False: ekf_update with the last k = 2 states as consider states, parameters exactly kept
    a.update(y, learn=False)
    want, _ = ekf_update(prior, y, a.C, a.R, a.gate, 2)
    np.testing.assert_allclose(a.state.theta, want.theta[:tables.n], rtol=0, atol=1e-9)
    assert a.parameters == Parameters()
    # the default learns: the parameters move, as ekf_update without consider states moves them
    b.update(y)
    want, _ = ekf_update(prior, y, b.C, b.R, b.gate, 0)
    np.testing.assert_allclose(b._x.theta, want.theta, rtol=0, atol=1e-9)
    assert b.parameters.lamp_efficiency != 0.0


def test_predict_uses_the_estimated_parameters_and_the_centre_by_default(tables) -> None:
    """theta^- = F(theta, u; eta, p) with the current estimate p (eq. 14); eta defaults to 0 (the centre)."""
    model = ParametricModel(tables, OSC, motion="position_aware", calibrated=("lamp_efficiency",))
    p0 = Parameters(lamp_efficiency=0.2)
    theta0 = np.linspace(600.0, 900.0, tables.n)
    u = np.full(6, 0.6)
    est = JointEstimator(model, DOUBLE, theta0, p0)
    est.predict(u)
    np.testing.assert_allclose(est.state.theta, model.step(theta0, u, 0.0, p0), rtol=1e-14)
    # and the nominal model (p = 0) would differ: the test can see the parameter
    assert np.abs(model.step(theta0, u, 0.0, Parameters()) - est.state.theta).max() > 1e-3


def _kit(tables, **kw):
    model = ParametricModel(tables, OSC, motion="position_aware", calibrated=ALL3, **kw)
    return model, JointEstimator(model, DOUBLE, 300.0)


def _phi(est, model, theta, u, eta, p):
    return est._jacobian(model.evaluate(theta, u, eta, p), eta, p)


def _assert_exact(Phi, model, theta, u, eta, p) -> None:
    n = model.n
    J, Jp = model.jac_theta(theta, u, eta, p), model.jac_p(theta, u, eta, p)
    np.testing.assert_allclose(Phi[:n, :n], J, rtol=0, atol=1e-12 * np.abs(J).max())
    np.testing.assert_allclose(Phi[:n, n:], Jp, rtol=0, atol=1e-12 * np.abs(Jp).max())
    np.testing.assert_array_equal(Phi[n:, :n], 0.0)
    np.testing.assert_array_equal(Phi[n:, n:], np.eye(len(model.calibrated)))


def test_the_kept_jacobian_follows_the_parameters(tables) -> None:
    """Phi_x against the model's exact Jacobians after each change of the parameters (and of the state): the
    per-position pieces and their kept sum must be rebuilt whenever a parameter moved by more than
    PARAMETER_TOLERANCE, whichever its sign, and after any combination of rebuilt pieces."""
    model, est = _kit(tables)
    theta = np.linspace(500.0, 900.0, tables.n)
    u, eta = np.full(6, 0.6), 0.0131
    seq = [
        (theta, Parameters(0.0, 0.05, 0.1)),
        (theta, Parameters(0.0, -0.05, -0.1)),  # both signs flipped: a change of 0.1 and 0.2
        (theta, Parameters(0.0, -0.05, 0.3)),  # the convection alone, twice in a row
        (theta, Parameters(0.0, -0.05, 0.5)),
        (theta + 10.0, Parameters(0.0, -0.05, 0.7)),  # the state and the convection together
        (theta + 10.0, Parameters(0.0, -0.05, 0.7)),  # nothing changed
    ]
    stale = _phi(est, model, theta, u, eta, Parameters())
    for th, p in seq:
        Phi = _phi(est, model, th, u, eta, p)
        _assert_exact(Phi, model, th, u, eta, p)
    # the test sees a stale theta block: the one at p = 0 differs by far more than the tolerance above
    n = model.n
    assert np.abs(stale[:n, :n] - Phi[:n, :n]).max() > 1e-6 * np.abs(Phi[:n, :n]).max()


@pytest.mark.parametrize("what", ["convection", "emissivity", "node"])
def test_a_change_at_the_tolerance_keeps_the_jacobian(tables, what) -> None:
    """A parameter moved by exactly PARAMETER_TOLERANCE, or a node by exactly ``ekf.jacobian_tolerance`` K,
    is not "moved more than": the theta block stays the one already built (bit for bit); a little more
    rebuilds it."""
    model, est = _kit(tables)
    theta = np.linspace(500.0, 900.0, tables.n)
    u, eta, p = np.full(6, 0.6), 0.0131, Parameters()
    n = model.n
    first = _phi(est, model, theta, u, eta, p)[:n, :n].copy()
    tol = CFG.ekf.jacobian_tolerance
    assert tol == 2.0 and PARAMETER_TOLERANCE == 5e-3  # exact in binary: the differences below are exact

    def moved(step: float):
        if what == "node":
            th = theta.copy()
            th[3] += step * tol / PARAMETER_TOLERANCE
            return th, p
        return theta, Parameters(**{what: step})

    th, q = moved(PARAMETER_TOLERANCE)
    np.testing.assert_array_equal(_phi(est, model, th, u, eta, q)[:n, :n], first)
    th, q = moved(2 * PARAMETER_TOLERANCE)
    again = _phi(est, model, th, u, eta, q)[:n, :n]
    assert not np.array_equal(again, first)
    _assert_exact(_phi(est, model, th, u, eta, q), model, th, u, eta, q)


def test_nothing_changed_hands_out_the_kept_sum(tables) -> None:
    """Without calibrated parameters Phi is the kept theta block itself: a sample with nothing changed gets
    the very same array (issue 21's saving), one with a changed state a new one."""
    model = ParametricModel(tables, OSC, motion="position_aware")
    est = JointEstimator(model, CFG, 300.0)
    theta, u, p = np.linspace(500.0, 900.0, tables.n), np.full(6, 0.6), Parameters()
    a = _phi(est, model, theta, u, 0.0131, p)
    assert _phi(est, model, theta, u, 0.0131, p) is a
    assert _phi(est, model, theta + 5.0, u, 0.0131, p) is not a


@pytest.mark.parametrize("heat_capacity", ["constant", "temperature"])
def test_phi_is_in_the_covariance_precision(tables, heat_capacity) -> None:
    for cfg, dtype in ((CFG, np.float32), (DOUBLE, np.float64)):
        for calibrated in ((), ("lamp_efficiency",)):
            model = ParametricModel(tables, OSC, motion="position_aware", calibrated=calibrated,
                                    heat_capacity=heat_capacity)
            est = JointEstimator(model, cfg, 300.0)
            Phi = _phi(est, model, np.linspace(500.0, 900.0, tables.n), np.full(6, 0.6), 0.0, Parameters())
            assert Phi.dtype == dtype, (cfg.ekf.covariance_precision, calibrated)


@pytest.mark.parametrize("oscillation", [None, OSC], ids=["fixed", "oscillating"])
def test_reported_covariance_adds_the_model_errors_q(tables, oscillation) -> None:
    """P_rep^- - P^- = Q_rep - Q after one predict from the same P0 with the same Phi (eq. 15 twice), with
    Q_rep of the specimen's mode (small_config: fixed q0 = 4.77e-4, q1 = 0; oscillating q0 = 2.37e-5,
    q1 = 1.88) and Q the filter's (ekf.q0, ekf.q1)."""
    model = ParametricModel(tables, oscillation, calibrated=("lamp_efficiency",))
    est = JointEstimator(model, DOUBLE, 800.0)
    est.predict(np.full(6, 0.5))
    me = CFG.ekf.model_error
    q0, q1 = (me.q0, me.q1) if oscillation is None else (me.oscillating.q0, me.oscillating.q1)
    assert (q0, q1) == ((4.77e-4, 0.0) if oscillation is None else (2.37e-5, 1.88))
    M = tables.fe.M
    want = process_noise(M, q0, q1) - process_noise(M, CFG.ekf.q0, CFG.ekf.q1)
    np.testing.assert_allclose(est.reported_P - est.state.P, want, rtol=0, atol=1e-9 * np.abs(want).max())


def _no_tc_tolerance():
    return DOUBLE.with_overrides({"ekf.model_error.tc_tolerance_fixed": 0.0,
                                  "ekf.model_error.tc_tolerance_relative": 0.0})


def test_reported_covariance_takes_the_filters_gain(tables) -> None:
    """Without the TCs' tolerance the reported update is the Joseph form with the filter's own gain K:
    P_rep = (I - K C) P_rep^- (I - K C)^T + K R K^T."""
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency",))
    est = JointEstimator(model, _no_tc_tolerance(), 800.0)
    est.predict(np.full(6, 0.5))
    before = est.reported.P.copy()
    est.update(np.array([810.0, 805.0, 812.0]))
    K = est.last_info.gain
    I_KC = np.eye(before.shape[0]) - K @ est.C
    want = I_KC @ before @ I_KC.T + K @ est.R @ K.T
    np.testing.assert_allclose(est.reported.P, want, rtol=0, atol=1e-9 * np.abs(want).max())


def test_the_tc_tolerance_widens_the_reported_covariance(tables) -> None:
    """small_config's TC tolerance (1.5 K, 0.4 %): the TCs' unknown deviations are carried, so after an update
    the reported temperature covariance is wider than without them (same filter, same readings)."""
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency",))
    with_tol, without = JointEstimator(model, DOUBLE, 800.0), JointEstimator(model, _no_tc_tolerance(), 800.0)
    assert with_tol.reported.P.shape[0] == tables.n + 1 + 3  # theta, the parameter, one deviation per TC read
    for est in (with_tol, without):
        est.predict(np.full(6, 0.5))
        est.update(np.array([810.0, 805.0, 812.0]))
    np.testing.assert_array_equal(with_tol.state.P, without.state.P)  # the filter is the same
    assert np.trace(with_tol.reported_P) > np.trace(without.reported_P) + 1e-6


def test_without_a_model_error_the_filters_covariance_is_reported(tables) -> None:
    cfg = DOUBLE.with_overrides({"ekf.model_error": None})
    model = ParametricModel(tables, None, calibrated=("lamp_efficiency",))
    est = JointEstimator(model, cfg, 800.0)
    assert est.reported is None and np.isnan(est.nis)
    est.predict(np.full(6, 0.5))
    np.testing.assert_array_equal(est.reported_P, est.state.P)
    # NIS per reading of the update: nu^T S^-1 nu / 3 with S = C P^- C^T + R, nu = y - C x^- (by hand)
    y = np.array([810.0, 805.0, 812.0])
    x, P = est._x.theta.copy(), est._x.P.copy()
    est.update(y)
    nu = y - est.C @ x
    S = est.C @ P @ est.C.T + est.R
    assert est.nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)) / 3, rel=1e-9)
    np.testing.assert_array_equal(est.reported_P, est.state.P)


def test_set_model_keeps_the_estimate_and_switches_the_model(tables) -> None:
    fixed = ParametricModel(tables, None, motion="position_aware", calibrated=("lamp_efficiency",))
    moving = ParametricModel(tables, OSC, motion="position_aware", calibrated=("lamp_efficiency",))
    a = JointEstimator(fixed, DOUBLE, 700.0)
    b = JointEstimator(moving, DOUBLE, 700.0)
    u = np.full(6, 0.5)
    a.predict(u, 0.01), b.predict(u, 0.01)  # different models, different estimates
    a._x = EKFState(b._x.theta.copy(), b._x.P.copy())
    a.set_model(moving)  # from now on the same model as b: the same predictions
    a.predict(u, 0.012), b.predict(u, 0.012)
    np.testing.assert_allclose(a.state.theta, b.state.theta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.state.P, b.state.P, rtol=0, atol=1e-9 * np.abs(b.state.P).max())
    with pytest.raises(ValueError, match="other parameters"):
        a.set_model(ParametricModel(tables, OSC, calibrated=("emissivity",)))
