"""Discrete-time FE model (paper eqs. 9-12a): Jacobians, CasADi expression and energy balance."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.model.discrete import discrete_model
from twin.model.fe import FEModel
from twin.physics.boundary import face_loss_coefficients, inert_gas_temperature
from twin.scenario import OscillationSpec

CFG = small_config()
OSC = OscillationSpec(enabled=True, amplitude=0.048, period=18.0)


@pytest.fixture(scope="module")
def fe() -> FEModel:
    return FEModel(CFG)


@pytest.fixture(scope="module")
def models(small_radiation, fe):
    radiation = small_radiation
    return {"fixed": discrete_model(CFG, radiation, None, fe=fe), "osc": discrete_model(CFG, radiation, OSC, fe=fe)}


def _state(fe: FEModel) -> np.ndarray:
    """A smooth non-uniform field 700..1150 K, hotter in the middle (like a heat-up)."""
    nodes = fe.nodes()
    s = CFG.specimen
    bump = np.sin(np.pi * nodes[:, 0] / s.length) * np.sin(np.pi * nodes[:, 1] / s.width)
    return 700.0 + 450.0 * bump


U = np.array([0.9, 0.7, 0.5, 0.4, 0.6, 0.3])


@pytest.mark.parametrize("kind", ["fixed", "osc"])
def test_jacobians_match_finite_differences(models, fe, kind) -> None:
    model = models[kind]
    th = _state(fe)
    J = model.jac_theta(th, U)
    h = 0.05  # K; central differences: truncation ~ h^2 |F'''| / 6 with F''' ~ t_s |A| 24 T ~ 1e-9 K^-2
    J_fd = np.stack([(model.step(th + h * e, U) - model.step(th - h * e, U)) / (2 * h) for e in np.eye(model.n)], 1)
    # rounding: 1e-16 x |F| (1e3 K) / h = 2e-12; truncation ~1e-12; bound 1e-9 of the O(1) entries
    np.testing.assert_allclose(J, J_fd, atol=1e-9)
    Ju = model.jac_u(th, U)
    du = 0.01
    Ju_fd = np.stack([(model.step(th, U + du * e) - model.step(th, U - du * e)) / (2 * du) for e in np.eye(6)], 1)
    # F is affine in u: only rounding, 1e-16 x 1e3 K / 1e-2 = 1e-11
    np.testing.assert_allclose(Ju, Ju_fd, atol=1e-9)
    assert model.n == fe.n and model.m == 6 and model.t_s == CFG.sampling.t_s


def test_casadi_function_equals_numpy(models, fe) -> None:
    import casadi as ca

    model = models["osc"]
    th = _state(fe)
    for kind in ("MX", "SX"):
        F = model.casadi_step(kind)
        np.testing.assert_allclose(np.asarray(F(th, U)).ravel(), model.step(th, U), rtol=1e-12)
    theta = ca.MX.sym("theta", model.n)
    u = ca.MX.sym("u", model.m)
    F = model.casadi_step()
    jac = ca.Function("J", [theta, u], [ca.jacobian(F(theta, u), theta), ca.jacobian(F(theta, u), u)])
    Jt, Ju = (np.asarray(x) for x in jac(th, U))
    np.testing.assert_allclose(Jt, model.jac_theta(th, U), atol=1e-12)  # both exact: rounding only
    np.testing.assert_allclose(Ju, model.jac_u(th, U), atol=1e-12)


@pytest.mark.parametrize("kind", ["fixed", "osc"])
def test_total_heat_balance_matches_the_radiation_and_loss_models(models, small_radiation, fe, kind) -> None:
    """1^T rho M f = 1^T chi + 1^T gamma (1^T K = 0) for a uniform field, from first principles.

    The oracle evaluates the radiation module's own ``flux`` (eq. 4) on the FD cells at the
    eta positions of the motion, the face losses (6) and the edge losses (3a-d) directly.
    """
    model, radiation = models[kind], small_radiation
    s = CFG.specimen
    T = 950.0
    th = np.full(model.n, T)
    lhs = s.density * np.ones(model.n) @ fe.M @ model.rhs(th, U)  # W per unit thickness (W/m)
    u_lamp = CFG.group_matrix @ U * radiation.lamp_flux_max
    if kind == "fixed":
        q_r = radiation.flux(np.full(s.n_states, T), u_lamp, 0.0)
    else:  # period average of eq. (4) by the midpoint rule in time (independent of the exact weights)
        ts = (np.arange(4000) + 0.5) * OSC.period / 4000
        etas = OSC.amplitude * np.sin(2 * np.pi * ts / OSC.period)
        q_r = np.mean([radiation.flux(np.full(s.n_states, T), u_lamp, e) for e in etas], axis=0)
    d, b = face_loss_coefficients(CFG)
    cell_area = s.length * s.width / s.n_states
    faces = -cell_area * np.sum(q_r + d * T - b) / s.thickness
    h, ig = CFG.holders, CFG.inert_gas
    xs, wx = np.polynomial.legendre.leggauss(3)
    x = 0.5 * s.length * (xs + 1)
    tig_int = 0.5 * s.length * np.sum(wx * inert_gas_temperature(CFG, x))
    edges = -(h.alpha * s.width * (2 * T - h.temperature_upper - h.temperature_lower)) - ig.alpha * (
        2 * s.length * T - 2 * tig_int
    )
    # exact up to rounding for "fixed"; for "osc" the time quadrature (4000 samples) errs ~1e-7 relative
    assert lhs == pytest.approx(faces + edges, rel=1e-6)


def test_oscillation_changes_the_distribution_not_the_total(models, fe) -> None:
    """Paper section 2.3: the motion mainly redistributes heat; the averaged model differs from the
    fixed one in shape, while the total lamp input absorbed changes only a little."""
    dB = models["osc"].B - models["fixed"].B
    assert np.abs(dB).max() > 1e-3 * np.abs(models["fixed"].B).max()  # the averaging did something
    total_fixed = np.ones(fe.n) @ fe.M @ models["fixed"].B
    total_osc = np.ones(fe.n) @ fe.M @ models["osc"].B
    # |eta| <= 0.125 L_s moves the plate under the same lamps: total absorbed power within 6 %
    # (measured at most 3.2 % per group for the default furnace; twice that as margin for ray noise)
    np.testing.assert_allclose(total_osc, total_fixed, rtol=0.06)


def test_build_reuses_the_fe_matrices(small_radiation, fe) -> None:
    # the backend rebuilds the model when the user toggles oscillation; with a given FEModel only
    # the radiation average is redone (its cost is reported by the bench, not asserted here)
    model = discrete_model(CFG, small_radiation, OscillationSpec(enabled=True, amplitude=0.03, period=10.0), fe=fe)
    assert model.fe is fe and model.n == fe.M.shape[0]


def test_ekf_step_benchmark_times_the_normal_update(small_radiation, monkeypatch, caplog) -> None:
    """ekf_step_ms: the median of the timed predict + update pairs (a fake clock), none of them gated."""
    import logging
    from types import SimpleNamespace

    import twin.estimation.ekf as ekf

    clock = iter(np.cumsum([0.0] + [v for d in (3e-3, 1e-3, 2e-3, 9e-3, 4e-3) for v in (d, 1.0)]))
    monkeypatch.setattr(ekf, "time", SimpleNamespace(perf_counter=lambda: float(next(clock))))
    with caplog.at_level(logging.WARNING, logger="twin.estimation.ekf"):
        ms = ekf.ekf_step_ms(CFG, small_radiation, repeats=5)
    assert ms == pytest.approx(3.0)  # median of 3, 1, 2, 9, 4 ms
    # readings from the model itself, the estimate 20 K off: the normal path, no reading gated
    assert not caplog.records


def test_steady_state_and_holding_powers(models) -> None:
    """f(theta_s, u) = 0 from the default start; hold_powers puts the steady fillet mean where asked."""
    model = models["fixed"]
    theta = model.steady_state(U)  # Newton from the default 1000 K start
    # Newton stops below 1e-9 K per step: the rates left are of that order times the largest rate (~1/s)
    assert np.max(np.abs(model.rhs(theta, U))) < 1e-6
    assert theta.min() > 300.0  # a physical field, not a spurious root
    d = np.array([1.0, 0.5, 0.5, 1.0, 0.2, 0.2])
    u = model.hold_powers(1000.0, d)
    np.testing.assert_allclose(u / u.max(), d, rtol=1e-12)  # the distribution is kept, only scaled
    assert model.c_m @ model.steady_state(u, theta) == pytest.approx(1000.0, abs=1e-6)
    with pytest.raises(ValueError, match="more than u_max"):
        model.hold_powers(5000.0, d)  # far above what full power holds
