"""The coarse single shooting of the feedforward OCP (twin.control.shooting) on a linear model, fast.

Oracles, all independent of the module's code paths:

* Heun's method on a linear system theta' = A theta + B u has a closed form per substep:
  theta+ = (I + h A + h^2 A^2 / 2) theta + (h I + h^2 A / 2) B u; it is second order (the error against the
  matrix exponential falls 4x when the substeps double);
* the cost of eqs. (19)-(21) written out from those states;
* the input maps' derivatives against central differences, and smooth_min1 against its closed form and limits;
* the cache: a cost asked for twice at the same p is simulated once.

The model is a made-up 3-node linear plate (numbers chosen for a well-conditioned test, not the furnace's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from scipy.linalg import expm

from twin.control.shooting import CoarseShooting, FreeInputs, ScaledDistribution, heun_interval, smooth_min1

N, M, T_S = 3, 2, 0.1
A = np.array([[-0.30, 0.10, 0.00], [0.10, -0.35, 0.10], [0.00, 0.10, -0.25]])  # 1/s
B = np.array([[40.0, 0.0], [20.0, 20.0], [0.0, 40.0]])  # K/s per unit input


@dataclass
class _Linear:
    """theta+ = theta + t_s (A theta + B u): eq. (12a)'s form, so f = (F - theta) / t_s = A theta + B u exactly."""

    n: int = N
    m: int = M
    t_s: float = T_S
    c_m: np.ndarray = None  # type: ignore[assignment]
    W: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        self.c_m = np.array([0.25, 0.5, 0.25])
        d = np.eye(N) - np.outer(np.ones(N), self.c_m)
        self.W = d.T @ np.diag(self.c_m) @ d  # the variance about the mean, eq. (21)'s form

    def step(self, theta, u):
        return np.asarray(theta, float) + T_S * (A @ np.asarray(theta, float) + B @ np.asarray(u, float))

    def jac_theta(self, theta, u):
        return np.eye(N) + T_S * A

    def jac_u(self, theta, u):
        return T_S * B


def _heun_closed_form(theta: np.ndarray, u: np.ndarray, dt: float, n_heun: int) -> np.ndarray:
    h = dt / n_heun
    Phi = np.eye(N) + h * A + 0.5 * h * h * A @ A
    Gam = (h * np.eye(N) + 0.5 * h * h * A) @ B
    for _ in range(n_heun):
        theta = Phi @ theta + Gam @ u
    return theta


@pytest.mark.parametrize("n_heun", [1, 3, 8])
def test_heun_interval_is_the_closed_form_of_heuns_method(n_heun: int) -> None:
    theta, u = np.array([900.0, 950.0, 1000.0]), np.array([0.4, 0.7])
    got = heun_interval(_Linear(), theta, u, 2.0, n_heun)
    np.testing.assert_allclose(got, _heun_closed_form(theta, u, 2.0, n_heun), rtol=0, atol=1e-9)


def test_heun_interval_is_second_order() -> None:
    theta, u, dt = np.array([900.0, 950.0, 1000.0]), np.array([0.4, 0.7]), 4.0
    # exact: theta(dt) = e^{A dt} theta + A^-1 (e^{A dt} - I) B u
    E = expm(A * dt)
    exact = E @ theta + np.linalg.solve(A, (E - np.eye(N)) @ (B @ u))
    err = [np.max(np.abs(heun_interval(_Linear(), theta, u, dt, k) - exact)) for k in (8, 16, 32)]
    # measured 4.21 and 4.10 (h = 0.5, 0.25 s against time constants of 2-4 s: near the asymptotic 4)
    assert err[0] / err[1] == pytest.approx(4.0, rel=0.1) and err[1] / err[2] == pytest.approx(4.0, rel=0.05)


def _shooting(inputs, reg=None) -> CoarseShooting:
    K = inputs.K
    T_knots = np.linspace(950.0, 1050.0, K + 1)
    weights = np.linspace(1.0, 2.0, K)
    return CoarseShooting(_Linear(), np.array([950.0, 940.0, 960.0]), 1.5, 2, T_knots, weights, g0=2.0, g1=0.5,
                          inputs=inputs, reg=reg)


def test_simulate_gives_the_cost_of_eqs_19_to_21_and_counts_itself() -> None:
    K = 4
    inputs = FreeInputs(M, K)
    reg = np.linspace(0.1, 0.8, M * K)
    sh = _shooting(inputs, reg)
    rng = np.random.default_rng(5)
    p = rng.uniform(0.1, 0.9, M * K)
    cost, traj = sh.simulate(p)
    theta, want = sh.theta0.copy(), 0.0
    model = _Linear()
    for k in range(K):
        theta = _heun_closed_form(theta, p[M * k: M * (k + 1)], sh.dt, sh.n_heun)
        np.testing.assert_allclose(traj[k + 1], theta, atol=1e-9)
        e = model.c_m @ theta - sh.T_knots[k + 1]
        want += sh.weights[k] * (2.0 * e * e + 0.5 * theta @ model.W @ theta)
    want += reg @ (p * p)
    assert cost == pytest.approx(want, rel=1e-12)
    np.testing.assert_array_equal(traj[0], sh.theta0)
    sh.simulate(p)
    assert sh.n_simulations == 2


def test_cost_is_cached_and_agrees_with_the_sweep() -> None:
    sh = _shooting(FreeInputs(M, 3))
    p = np.full(M * 3, 0.5)
    c = sh.cost(p)
    assert sh.cost(p) == c and sh.n_simulations == 1  # the second call is the cache's
    q = p + 0.01
    swept = sh.sweep(q)
    assert sh.cost(q) == swept.cost and sh.n_simulations == 1  # the sweep's result is remembered too
    assert sh.sweep(q) is swept and sh.n_sweeps == 1


@pytest.mark.parametrize("kind", ["free", "scaled"])
def test_gradient_and_gauss_newton_hessian_on_a_linear_model(kind: str) -> None:
    """On a linear model with free inputs the cost is quadratic in p: the gradient and the Gauss-Newton Hessian
    are exact (central differences); with the scaled distribution (eq. 18) the gradient still is."""
    K = 3
    inputs = FreeInputs(M, K) if kind == "free" else ScaledDistribution(M, K, width=0.05)
    sh = _shooting(inputs, reg=np.full(inputs.n_params, 0.3))
    rng = np.random.default_rng(11)
    p = rng.uniform(0.2, 0.8, inputs.n_params) if kind == "free" else np.r_[0.5, 0.5, rng.uniform(0.6, 1.2, K)]
    res = sh.sweep(p)
    h = 1e-4
    eye = np.eye(p.size)
    fd = np.array([(sh.simulate(p + h * e)[0] - sh.simulate(p - h * e)[0]) / (2 * h) for e in eye])
    np.testing.assert_allclose(res.grad, fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(fd)))
    if kind == "free":
        H = np.array([[(sh.simulate(p + h * a + h * b)[0] - sh.simulate(p + h * a - h * b)[0]
                        - sh.simulate(p - h * a + h * b)[0] + sh.simulate(p - h * a - h * b)[0]) / (4 * h * h)
                       for b in eye] for a in eye])
        np.testing.assert_allclose(res.hess, H, rtol=1e-4, atol=1e-4 * np.max(np.abs(H)))


def test_smooth_min1_and_its_derivatives() -> None:
    z = np.linspace(-1.0, 3.0, 41)
    w = 0.1
    s, ds, d2s = smooth_min1(z, w)
    np.testing.assert_allclose(s, 0.5 * (z + 1.0 - np.sqrt((z - 1.0) ** 2 + w * w)), atol=1e-15)
    h = 1e-5
    np.testing.assert_allclose(ds, (smooth_min1(z + h, w)[0] - smooth_min1(z - h, w)[0]) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(d2s, (smooth_min1(z + h, w)[1] - smooth_min1(z - h, w)[1]) / (2 * h), atol=1e-5)
    far = smooth_min1(np.array([-50.0, 50.0]), w)[0]
    np.testing.assert_allclose(far, [-50.0, 1.0], atol=1e-3)  # min(z, 1) away from the corner
    assert np.all(s <= np.minimum(z, 1.0))  # below both branches


def test_scaled_distribution_derivatives_and_curvature() -> None:
    K = 4
    sd = ScaledDistribution(M, K, width=0.05)
    p = np.array([0.6, 0.4, 0.9, 1.3, 1.7, 2.2])  # d, then v: some inputs near and past saturation
    h = 1e-6
    U = sd.inputs(p)
    assert U.shape == (K, M) and sd.n_params == M + K
    for k in range(K):
        D, n_active = sd.input_derivatives(p, k)
        assert n_active == M + k + 1
        fd = np.array([(sd.inputs(p + h * e)[k] - sd.inputs(p - h * e)[k]) / (2 * h) for e in np.eye(p.size)]).T
        np.testing.assert_allclose(D, fd[:, :n_active], atol=1e-7)
        np.testing.assert_allclose(fd[:, n_active:], 0.0, atol=1e-9)  # later parameters do not act on u_k
    mu = np.random.default_rng(2).normal(size=(K, M))

    def weighted(q):
        return float(np.sum(mu * sd.inputs(q)))

    g = 1e-4
    eye = np.eye(p.size)
    H = np.array([[(weighted(p + g * a + g * b) - weighted(p + g * a - g * b) - weighted(p - g * a + g * b)
                    + weighted(p - g * a - g * b)) / (4 * g * g) for b in eye] for a in eye])
    np.testing.assert_allclose(sd.input_curvature(p, mu), H, atol=1e-5 * np.max(np.abs(H)))  # FD error ~ g^2


def test_free_inputs_map() -> None:
    fi = FreeInputs(M, 3)
    p = np.arange(6.0)
    np.testing.assert_array_equal(fi.inputs(p), p.reshape(3, M))
    D, n_active = fi.input_derivatives(p, 1)
    assert n_active == 4
    np.testing.assert_array_equal(D, np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]))
    assert not fi.input_curvature(p, np.ones((3, M))).any()
