"""NEES of a linear Kalman filter against its chi-square bounds, and the reported covariance of a suboptimal
filter (twin.estimation.consistency, twin.estimation.process_noise)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from twin.estimation.consistency import cell_nees, chi2_interval, coverage, nees
from twin.estimation.ekf import EKFState, ekf_update
from twin.estimation.process_noise import ReportedCovariance

# a damped 3-state system observed by 2 sensors (arbitrary, stable, not diagonal)
A = np.array([[0.95, 0.05, 0.0], [0.02, 0.9, 0.05], [0.0, 0.1, 0.85]])
C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
R = np.diag([0.5, 0.8])
Q_TRUE = np.array([[0.3, 0.1, 0.0], [0.1, 0.4, 0.1], [0.0, 0.1, 0.2]])
RUNS, STEPS = 200, 40


def _simulate(Q_filter: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RUNS Monte Carlo runs of the truth (process noise Q_TRUE) and a Kalman filter tuned with Q_filter;
    returns per step the mean NEES against the filter's own P and against the reported covariance (Q_TRUE
    propagated with the filter's gain), and the innovations' mean NIS per reading against the reported one."""
    rng = np.random.default_rng(seed)
    own, rep, nis = np.zeros(STEPS), np.zeros(STEPS), np.zeros(STEPS)
    for _ in range(RUNS):
        x = rng.multivariate_normal(np.zeros(3), np.eye(3))
        state = EKFState(np.zeros(3), np.eye(3))
        report = ReportedCovariance(np.eye(3), Q_TRUE)
        for k in range(STEPS):
            x = A @ x + rng.multivariate_normal(np.zeros(3), Q_TRUE)
            state = EKFState(A @ state.theta, A @ state.P @ A.T + Q_filter)
            report.predict(A)
            y = C @ x + rng.multivariate_normal(np.zeros(2), R)
            state, info = ekf_update(state, y, C, R, gate=np.inf)
            report.update(info.gain, C, R, info.innovation, info.used)
            own[k] += nees(state.theta - x, state.P) / RUNS
            rep[k] += nees(state.theta - x, report.P) / RUNS
            nis[k] += report.nis / RUNS
    return own, rep, nis


def test_nees_of_a_matched_filter_lies_within_the_chi_square_bounds() -> None:
    """Q_filter = Q_TRUE: the filter is optimal, its own P is the error covariance and the reported one equals
    it.  The mean NEES over 200 runs at each step lies in the 99 % region of chi2(3 * 200) / 200 (so about one
    step in a hundred may fall out by chance: allow two of 40)."""
    own, rep, nis = _simulate(Q_TRUE, seed=11)
    lo, hi = chi2_interval(dof=3, runs=RUNS, probability=0.99)
    assert np.sum((own < lo) | (own > hi)) <= 2, own
    np.testing.assert_allclose(rep, own, rtol=1e-9)
    lo2, hi2 = chi2_interval(dof=2, runs=RUNS, probability=0.99)  # NIS per reading: chi2(2) / 2
    assert np.sum((2 * nis < lo2) | (2 * nis > hi2)) <= 2, nis


def test_the_reported_covariance_of_a_mistuned_filter_is_consistent_where_its_own_p_is_not() -> None:
    """A filter tuned with a tenth of the true process noise is over-confident: its own NEES leaves the
    chi-square region (a plausible bug: reporting the filter's P).  The reported covariance (the true Q
    propagated with the filter's actual gain) is the error covariance of that suboptimal filter: its NEES
    stays inside."""
    own, rep, _ = _simulate(0.1 * Q_TRUE, seed=12)
    lo, hi = chi2_interval(dof=3, runs=RUNS, probability=0.99)
    assert np.mean(own[10:] > hi) > 0.9, own
    assert np.sum((rep < lo) | (rep > hi)) <= 2, rep


def test_reported_update_is_the_joseph_form_written_out() -> None:
    """(I - L C) P (I - L C)^T + L R L^T for a gain that is not the optimal one (here: half of it)."""
    rng = np.random.default_rng(2)
    F = rng.normal(size=(3, 3))
    P = F @ F.T + np.eye(3)
    L = 0.5 * P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    rep = ReportedCovariance(P, np.zeros((3, 3)))
    rep.update(L, C, R, np.array([0.3, -0.2]), np.array([True, True]))
    I_LC = np.eye(3) - L @ C
    np.testing.assert_allclose(rep.P, I_LC @ P @ I_LC.T + L @ R @ L.T, rtol=1e-12)


def test_coverage_and_cell_nees() -> None:
    err = np.array([[0.0, 1.0], [2.5, -1.9]])
    assert coverage(err, np.ones_like(err)) == 0.75  # 2.5 > 2 sigma, -1.9 within
    assert np.isnan(coverage(np.array([np.nan]), np.ones(1)))
    z = cell_nees(err, np.zeros_like(err), np.full_like(err, 2.0), np.array([True, False]))
    np.testing.assert_allclose(z, [0.0, (2.5 / 2) ** 2])


@pytest.mark.parametrize("bias", [False, True])
def test_the_reported_covariance_leaves_the_estimate_bit_for_bit(bias: bool) -> None:
    """[ekf.model_error] changes what the twin reports, never its estimate: the joint filter with and without it
    (small furnace, calibrating, position-aware, 30 samples of a heat-up with a reading 2 K off) gives identical
    theta and filter P, while the reported covariance differs from the filter's; also with the model's bias
    carried (shape and per node, consider states)."""
    from twin.config import small_config
    from twin.estimation.choice import build_estimator
    from twin.model.tables import model_tables
    from twin.radiation import radiation_model
    from twin.scenario import EstimatorChoice

    cfg = small_config()
    if bias:
        cfg = cfg.with_overrides({"ekf.model_error.bias_degree": 1, "ekf.model_error.bias_variance": [0.04, 1e-3, 1e-3],
                                  "ekf.model_error.bias_node_variance": 2e-3})
    assert cfg.ekf.model_error is not None
    plain = cfg.with_overrides({"ekf.model_error": None})
    tables = model_tables(cfg, radiation_model(cfg))
    a = build_estimator(EstimatorChoice(), tables, None, cfg, 300.0)
    b = build_estimator(EstimatorChoice(), tables, None, plain, 300.0)
    assert a.reported is not None and b.reported is None
    u = np.full(6, 0.6)
    for j in range(30):
        y = np.array([300.0 + 2.0 * j, 302.0 + 2.0 * j, 300.0 + 2.0 * j])
        for est in (a, b):
            est.update(y, learn=j > 10)
            est.predict(u, 0.0)
    np.testing.assert_array_equal(a.state.theta, b.state.theta)
    np.testing.assert_array_equal(a.state.P, b.state.P)
    np.testing.assert_array_equal(b.reported_P, b.state.P)  # without model error the filter's P is reported
    assert not np.allclose(a.reported_P, a.state.P)
    assert a.reported.P.shape[0] == a.n + a.k + 3 + (3 + a.n if bias else 0)  # TCs' deviations, the bias


#: faster dynamics for the deviations' test: the cross-covariance of error and deviations then decays between
#: samples, so forgetting to propagate it shows (expected NEES 2.2 instead of 3; with A itself it hides)
A_FAST = 0.6 * A


def _simulate_biased(consider: bool, seed: int, runs: int = 200, steps: int = 40) -> np.ndarray:
    """Monte Carlo of the system above (A_FAST) whose sensors read a fixed deviation beta_i * 1.5 K each (beta_i uniform
    in [-1, 1] per run, the filter does not know it); returns per step the mean NEES of the estimate against the
    reported covariance (the true Q, with or without the deviations as consider states)."""
    rng = np.random.default_rng(seed)
    out = np.zeros(steps)
    for _ in range(runs):
        x = rng.multivariate_normal(np.zeros(3), np.eye(3))
        beta = rng.uniform(-1.0, 1.0, 2)
        state = EKFState(np.zeros(3), np.eye(3))
        report = ReportedCovariance(np.eye(3), Q_TRUE, readings=2, tc_tolerance=(1.5, 0.0) if consider else None)
        for k in range(steps):
            x = A_FAST @ x + rng.multivariate_normal(np.zeros(3), Q_TRUE)
            state = EKFState(A_FAST @ state.theta, A_FAST @ state.P @ A_FAST.T + Q_TRUE)
            report.predict(A_FAST)
            y = C @ x + 1.5 * beta + rng.multivariate_normal(np.zeros(2), R)
            state, info = ekf_update(state, y, C, R, gate=np.inf)
            report.update(info.gain, C, R, info.innovation, info.used, y)
            out[k] += nees(state.theta - x, report.P[:3, :3]) / runs
    return out


def _consistent_only_when_carried(simulate: Callable[..., np.ndarray], seed: int) -> None:
    """``simulate(carried, seed=...)`` gives the mean NEES per step over 200 runs (3 states): without the consider
    states it leaves the 99 % chi-square region for good (over 90 % of the steps after 20), with them it stays
    inside (at most 2 steps of 40 out)."""
    lo, hi = chi2_interval(dof=3, runs=200, probability=0.99)
    without = simulate(False, seed=seed)
    assert np.mean(without[20:] > hi) > 0.9, without
    carried = simulate(True, seed=seed)
    assert np.sum((carried < lo) | (carried > hi)) <= 2, carried


def test_consider_states_make_the_reported_covariance_consistent_under_fixed_sensor_deviations() -> None:
    """Each sensor reads a deviation fixed for the run (a TC's tolerance, uniform over +-1.5 K): the filter,
    matched to the white noise, pulls its estimate towards the biased readings.  Without the deviations in the
    reported covariance its NEES leaves the chi-square region (the error the issue measured: a constant error
    that white Q cannot represent); with them as Schmidt-Kalman consider states (variance 1.5^2 / 3) it stays
    inside.  Expected NEES (exact, from the covariances): 3.0 with, 5.1 without.  Planted bug: not propagating the
    cross-covariance in ``predict`` (P[:m, m:] kept) gives 2.2 and fails it.
    The NEES is not exactly chi-square here (beta is uniform, not Gaussian), but its mean is dof when the
    covariance is right, which the 99 % region of chi2(3 * 200) / 200 tests for."""
    _consistent_only_when_carried(_simulate_biased, seed=21)


def test_reported_nis_and_consider_update_with_every_reading_and_with_one_missing() -> None:
    """The reported NIS is nu^T S_a^-1 nu / p with S_a = C_a P C_a^T + R over the readings used, and the
    consider states' update stays finite when a reading is missing (its deviation is not carried that sample):
    the update's fast path (all readings used, issue 21) and its general path against the formulas written out."""
    rng = np.random.default_rng(5)
    F = rng.normal(size=(3, 3))
    P = F @ F.T + np.eye(3)
    L = 0.5 * P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    fixed = 1.5  # K, the tolerance below 375 C (thermocouple_tolerance)
    Pa = np.zeros((5, 5))
    Pa[:3, :3], Pa[3:, 3:] = P, np.eye(2) / 3.0
    Ca = np.concatenate([C, fixed * np.eye(2)], axis=1)
    nu = np.array([0.3, -0.2])
    rep = ReportedCovariance(P, np.zeros((3, 3)), readings=2, tc_tolerance=(fixed, 0.0))
    rep.update(L, C, R, nu, np.array([True, True]), np.array([300.0, 301.0]))
    S = Ca @ Pa @ Ca.T + R
    assert rep.nis == pytest.approx(float(nu @ np.linalg.inv(S) @ nu) / 2, rel=1e-12)
    La = np.concatenate([L, np.zeros((2, 2))])
    I_LC = np.eye(5) - La @ Ca
    np.testing.assert_allclose(rep.P, I_LC @ Pa @ I_LC.T + La @ R @ La.T, rtol=1e-12, atol=1e-14)
    # the second TC missing: the gain's column for it is zero, its deviation drops out of C_a this sample
    one = ReportedCovariance(P, np.zeros((3, 3)), readings=2, tc_tolerance=(fixed, 0.0))
    L1 = L.copy()
    L1[:, 1] = 0.0
    one.update(L1, C, R, np.array([0.3, np.nan]), np.array([True, False]), np.array([300.0, np.nan]))
    C1 = Ca.copy()
    C1[1, 4] = 0.0
    S1 = C1 @ Pa @ C1.T + R
    assert one.nis == pytest.approx(0.3**2 / S1[0, 0], rel=1e-12)
    assert np.all(np.isfinite(one.P))


#: the model bias's shape: a forcing on the unobserved middle state (and half of it on the third)
G_BIAS = np.array([[0.0], [1.0], [0.5]])
BIAS_VARIANCE = 0.5


def _simulate_model_bias(carried: bool, seed: int, runs: int = 200, steps: int = 40) -> np.ndarray:
    """Monte Carlo of the system above whose dynamics have a constant forcing G_BIAS c per run
    (c ~ N(0, BIAS_VARIANCE), the filter does not know it: the model's own bias); returns per step the mean NEES
    of the estimate against the reported covariance (the true Q, with or without the bias as consider states).
    The filter is linear and ungated, so its gains and the reported covariance are the same in every run: one
    filter gives them, the runs' states and estimates are propagated together."""
    rng = np.random.default_rng(seed)
    out = np.zeros(steps)
    LQ, LR = np.linalg.cholesky(Q_TRUE), np.sqrt(np.diag(R))
    x = rng.standard_normal((runs, 3))
    c = rng.normal(0.0, np.sqrt(BIAS_VARIANCE), (runs, 1))
    x_hat = np.zeros((runs, 3))
    state = EKFState(np.zeros(3), np.eye(3))
    report = ReportedCovariance(np.eye(3), Q_TRUE, bias_shape=G_BIAS if carried else None,
                                bias_variance=np.array([BIAS_VARIANCE]) if carried else None)
    for k in range(steps):
        x = x @ A.T + c @ G_BIAS.T + rng.standard_normal((runs, 3)) @ LQ.T
        x_hat = x_hat @ A.T
        state = EKFState(A @ state.theta, A @ state.P @ A.T + Q_TRUE)
        report.predict(A)
        y = x @ C.T + LR * rng.standard_normal((runs, 2))
        state, info = ekf_update(state, y[0], C, R, gate=np.inf)
        report.update(info.gain, C, R, info.innovation, info.used, y[0])
        x_hat = x_hat + (y - x_hat @ C.T) @ info.gain.T
        out[k] = np.mean([nees(e, report.P[:3, :3]) for e in x_hat - x])
    return out


def test_a_model_bias_carried_as_consider_states_makes_the_reported_covariance_consistent() -> None:
    """The model misses a forcing that is constant for the run (banded's structured error, issue 25): the filter,
    matched to the white noise, leaves a steady error where its sensors do not read.  Without the bias in the
    reported covariance the NEES leaves the chi-square region; with it as Schmidt-Kalman consider states
    (Phi_a's G block, process_noise module docstring) it stays inside (c Gaussian here, so the NEES is
    chi-square).  Planted bugs that fail it (and the exact test below): the cross-covariance of error and bias
    not propagated (``P[:m, m:] += G P_cz`` left out of ``predict``), the cross terms X + X^T left out of P_xx,
    the bias's own term G P_cc G^T left out."""
    _consistent_only_when_carried(_simulate_model_bias, seed=31)


def test_reported_predict_with_tc_deviations_and_model_bias_is_the_augmented_form_written_out() -> None:
    """Phi_a P_a Phi_a^T + Q_a with Phi_a = [[Phi, 0, s G], [0, I, 0], [0, 0, I]] (the state, the TCs' deviations,
    the bias's coefficients; s the bias's growth with the temperature) after an update that correlated them all;
    then the update with C_a = [C, tol, 0].  Planted bugs caught here: G P_cc G^T left out of ``predict``; the
    growth s applied to the cross terms but not to G P_cz."""
    rng = np.random.default_rng(7)
    F = rng.normal(size=(3, 3))
    P = F @ F.T + np.eye(3)
    G = rng.normal(size=(3, 2))
    var = np.array([0.4, 0.2])
    L = 0.5 * P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    rep = ReportedCovariance(P, Q_TRUE, readings=2, tc_tolerance=(1.5, 0.0), bias_shape=G, bias_variance=var,
                             bias_growth=(1000.0, 2.0))
    Pa = np.zeros((7, 7))
    Pa[:3, :3], Pa[3:5, 3:5], Pa[5:, 5:] = P, np.eye(2) / 3.0, np.diag(var)
    np.testing.assert_array_equal(rep.P, Pa)
    Ca = np.concatenate([C, 1.5 * np.eye(2), np.zeros((2, 2))], axis=1)
    La = np.concatenate([L, np.zeros((4, 2))])
    Qa = np.zeros((7, 7))
    Qa[:3, :3] = Q_TRUE
    for T, scale in ((None, 1.0), (1100.0, 1.21)):  # the second round from a P_a with every block filled, the
        Phi_a = np.eye(7)                              # bias grown by (1100 / 1000)^2
        Phi_a[:3, :3], Phi_a[:3, 5:] = A, scale * G
        rep.predict(A, T)
        Pa = Phi_a @ Pa @ Phi_a.T + Qa
        np.testing.assert_allclose(rep.P, Pa, rtol=1e-12, atol=1e-12)
        rep.update(L, C, R, np.array([0.3, -0.2]), np.array([True, True]), np.array([300.0, 301.0]))
        I_LC = np.eye(7) - La @ Ca
        Pa = I_LC @ Pa @ I_LC.T + La @ R @ La.T
        np.testing.assert_allclose(rep.P, Pa, rtol=1e-12, atol=1e-12)


def test_the_reported_covariance_takes_the_specimen_modes_model_error() -> None:
    """``[ekf.model_error]`` per mode (issue 25): an oscillating specimen's estimator reports with the q0 and
    bias_variance of ``[ekf.model_error.oscillating]``, a fixed one's with its own; unset, both take the fixed
    ones.  The bias's shape has zero rows for the calibrated parameters (it forces temperatures only).  Planted
    bug caught here: ``for_mode`` handing the fixed specimen the oscillating values."""
    from twin.config import small_config
    from twin.estimation.choice import build_estimator
    from twin.estimation.ekf import process_noise
    from twin.model.tables import model_tables
    from twin.radiation import radiation_model
    from twin.scenario import EstimatorChoice, OscillationSpec

    cfg = small_config().with_overrides({"ekf.model_error.q0": 2e-4, "ekf.model_error.bias_degree": 1,
                                         "ekf.model_error.bias_variance": [1e-4, 2e-4, 3e-4],
                                         "ekf.model_error.oscillating": {"q0": 5e-5, "representation_rms": 0.25,
                                                                         "bias_variance": [0.0, 0.0, 1e-5]}})
    me = cfg.ekf.model_error
    assert me.for_mode(False).representation_rms == me.representation_rms != 0.25  # the σ map's r per mode
    assert me.for_mode(True).representation_rms == 0.25 and me.for_mode(True).q1 == me.q1  # unset: the fixed one
    tables = model_tables(cfg, radiation_model(cfg))
    q1 = cfg.ekf.model_error.q1
    for osc, q0, var in ((None, 2e-4, [1e-4, 2e-4, 3e-4]), (OscillationSpec(enabled=False), 2e-4, [1e-4, 2e-4, 3e-4]),
                         (OscillationSpec(enabled=True), 5e-5, [0.0, 0.0, 1e-5])):
        est = build_estimator(EstimatorChoice(calibrate=True), tables, osc, cfg, 300.0)
        rep, n, k = est.reported, est.n, est.k
        assert rep is not None and k > 0 and rep.G is not None
        np.testing.assert_allclose(rep.Q[:n, :n], process_noise(est.model.fe.M, q0, q1), rtol=1e-12)
        np.testing.assert_array_equal(np.diag(rep.P)[-3:], var)
        assert rep.G.shape == (n + k, 3) and not rep.G[n:].any() and np.allclose(rep.G[:n, 0], 1.0)
    plain = cfg.with_overrides({"ekf.model_error.oscillating": None})
    est = build_estimator(EstimatorChoice(), tables, OscillationSpec(enabled=True), plain, 300.0)
    np.testing.assert_allclose(est.reported.Q[:est.n, :est.n], process_noise(est.model.fe.M, 2e-4, q1), rtol=1e-12)
    with pytest.raises(ValueError, match="bias_variance"):
        cfg.with_overrides({"ekf.model_error.bias_degree": 2})  # 3 variances for 6 terms


def test_the_estimator_grows_the_reported_bias_with_its_temperature() -> None:
    """``bias_exponent`` p: the bias's forcing this step is (mean of the estimated nodes / bias_temperature)^p
    times its value at bias_temperature; p = 0 or no bias carried: 1.  The estimator hands its mean temperature
    to the reported covariance.  Planted bug caught here: the ratio inverted (bias_temperature / T)."""
    from twin.config import small_config
    from twin.estimation.choice import build_estimator
    from twin.model.tables import model_tables
    from twin.radiation import radiation_model
    from twin.scenario import EstimatorChoice

    base = small_config()
    tables = model_tables(base, radiation_model(base))
    growth = {"ekf.model_error.bias_exponent": 2.0, "ekf.model_error.bias_temperature": 300.0}
    for overrides, expected in (({"ekf.model_error.bias_variance": [0.04], **growth}, 4.0),
                                ({"ekf.model_error.bias_variance": [0.04]}, 1.0), (growth, 1.0)):
        est = build_estimator(EstimatorChoice(), tables, None, base.with_overrides(overrides), 600.0)
        seen: list[float | None] = []
        inner = est.reported.predict

        def spy(Phi: np.ndarray, T: float | None = None, inner=inner, seen=seen) -> None:  # type: ignore[no-untyped-def]
            seen.append(T)
            inner(Phi, T)

        est.reported.predict = spy  # type: ignore[method-assign]
        est.predict(np.full(len(base.lamps.groups), 0.5), 0.0)
        assert seen == [pytest.approx(600.0)], overrides
        assert est.reported.bias_scale(600.0) == pytest.approx(expected), overrides


def test_the_per_node_bias_taken_as_a_slice_equals_the_dense_product() -> None:
    """G = [G_shape | [I; 0]] (each node's own forcing, and a zero row for a parameter): predict takes the identity
    block as a slice (``bias_identity``) and gives what the dense product gives.  Planted bug caught here: the
    slice's term left out of P_xc G^T."""
    rng = np.random.default_rng(9)
    m = 4  # three nodes and one parameter
    F = rng.normal(size=(m, m))
    P, Phi = F @ F.T + np.eye(m), 0.9 * np.eye(m) + 0.05 * rng.normal(size=(m, m))
    G = np.zeros((m, 2 + 3))
    G[:3, :2] = rng.normal(size=(3, 2))
    G[:3, 2:] = np.eye(3)
    var = np.array([0.3, 0.1, 0.02, 0.02, 0.02])
    C1 = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    L = 0.5 * P @ C1.T @ np.linalg.inv(C1 @ P @ C1.T + R)
    a, b = (ReportedCovariance(P, 0.01 * np.eye(m), bias_shape=G, bias_variance=var, bias_growth=(1000.0, 1.0),
                               bias_identity=k) for k in (3, 0))
    for rep in (a, b):
        for T in (1000.0, 1200.0):
            rep.predict(Phi, T)
            rep.update(L, C1, R, np.array([0.2, -0.1]), np.array([True, True]))
    np.testing.assert_allclose(a.P, b.P, rtol=1e-12, atol=1e-12)
