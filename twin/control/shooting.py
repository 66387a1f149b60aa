"""Single shooting of the discrete model on a coarse grid, with forward sensitivities.

The feedforward OCP (paper eq. 20, :mod:`twin.control.feedforward`) has few unknowns (a power
distribution and one amplification per knot) but a long horizon of a 117-state model.
This module evaluates, for a parameter vector p,

* the coarse trajectory theta_k at the knots t_k = t0 + k dt, integrating the model's
  right-hand side f(theta, u) = (F(theta, u) - theta) / t_s of eq. (12a) with Heun's
  method (explicit trapezoidal rule), the input linear between the knot values;
* the least-squares cost  sum_k w_k (g0 e_k^2 + g1 theta_k^T W theta_k)  (eqs. 19-21);
* its gradient and the Gauss-Newton Hessian 2 J_r^T J_r from the forward sensitivities
  S_k = d theta_k / d p, propagated with the model's Jacobians dF/dtheta (16) and dF/du
  (one BLAS-3 product per Heun stage).

The inputs at the knots and their derivatives come from an :class:`InputMap`, so the
same code serves the parametrized (eq. 18) and the free OCP (Remark 4).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from twin.model.dynamics import DiscreteDynamics
from twin.numerics import heun_step

Array = NDArray[np.float64]


class InputMap(Protocol):
    """Inputs held over the intervals as a function of the parameters p."""

    @property
    def n_params(self) -> int: ...

    def inputs(self, p: Array) -> Array:
        """U (K, m): the input held over interval k."""
        ...

    def input_derivatives(self, p: Array, k: int) -> tuple[Array, int]:
        """(dU_k, n_active): d u_k / d p (m, n_active); later parameters do not act on u_k."""
        ...

    def input_curvature(self, p: Array, mu: Array) -> Array:
        """sum_k,i mu_ki d^2 u_ki / d p^2 (n_params, n_params) for weights mu (K, m)."""
        ...


def smooth_min1(z: Array, width: float) -> tuple[Array, Array, Array]:
    """Smooth min(z, 1) = (z + 1 - sqrt((z - 1)^2 + w^2)) / 2 and its first two derivatives."""
    r = np.sqrt((z - 1.0) ** 2 + width**2)
    return 0.5 * (z + 1.0 - r), 0.5 * (1.0 - (z - 1.0) / r), -0.5 * width**2 / r**3


@dataclass(frozen=True)
class ScaledDistribution:
    """u_k = smin(v_k d) held over interval k, p = [d (m), v_0..v_K-1] (eq. 18, scaling 1^T d = 1).

    v is piecewise constant on the intervals: with v linear between knots, the
    trapezoidal (Heun) interval cannot see an odd-even oscillation of the knot values,
    and the OCP exploits that artefact; a held v has no such blind direction.
    """

    m: int
    K: int
    width: float

    @property
    def n_params(self) -> int:
        return self.m + self.K

    def inputs(self, p: Array) -> Array:
        d, v = p[: self.m], p[self.m:]
        return smooth_min1(np.outer(v, d), self.width)[0]  # (K, m)

    def input_derivatives(self, p: Array, k: int) -> tuple[Array, int]:
        n_active = self.m + k + 1
        d, v = p[: self.m], p[self.m:]
        _, ds, _ = smooth_min1(v[k] * d, self.width)
        D = np.zeros((self.m, n_active))
        D[:, : self.m] = np.diag(ds * v[k])
        D[:, self.m + k] = ds * d
        return D, n_active

    def input_curvature(self, p: Array, mu: Array) -> Array:
        m = self.m
        d, v = p[:m], p[m:]
        Z = np.outer(v, d)
        _, s1, s2 = smooth_min1(Z, self.width)  # (K, m)
        H = np.zeros((self.n_params, self.n_params))
        # d^2 u_ki / d d_i^2 = s'' v_k^2;  d^2 / d v_k^2 = s'' d_i^2;  d^2 / d d_i d v_k = s'' v_k d_i + s'
        H[np.arange(m), np.arange(m)] = np.sum(mu * s2 * (v**2)[:, None], axis=0)
        kk = m + np.arange(self.K)
        H[kk, kk] = np.sum(mu * s2 * (d**2)[None, :], axis=1)
        cross = mu * (s2 * Z + s1)  # (K, m)
        H[:m, m:] = cross.T
        H[m:, :m] = cross
        return H


@dataclass(frozen=True)
class FreeInputs:
    """Piecewise-constant free inputs: p = [u_0; ..; u_K-1] (K m), held over each interval."""

    m: int
    K: int

    @property
    def n_params(self) -> int:
        return self.m * self.K

    def inputs(self, p: Array) -> Array:
        return p.reshape(self.K, self.m)

    def input_derivatives(self, p: Array, k: int) -> tuple[Array, int]:
        n_active = self.m * (k + 1)
        D = np.zeros((self.m, n_active))
        D[:, self.m * k:] = np.eye(self.m)
        return D, n_active

    def input_curvature(self, p: Array, mu: Array) -> Array:
        return np.zeros((self.n_params, self.n_params))  # u = p is linear


@dataclass
class SweepResult:
    cost: float
    grad: Array | None
    hess: Array | None
    theta: Array  # (K + 1, n)


def heun_interval(model: DiscreteDynamics, theta: Array, u: Array, dt: float, n_heun: int) -> Array:
    """theta after dt under constant u: ``n_heun`` Heun sub-steps on f = (F(theta, u) - theta) / t_s (eq. 12a)."""
    t_s = model.t_s

    def f(_t: float, x: Array) -> Array:
        return (np.asarray(model.step(x, u), float) - x) / t_s

    h = dt / n_heun
    th = np.asarray(theta, float)
    for _ in range(n_heun):
        th = heun_step(f, 0.0, th, h)
    return th


class CoarseShooting:
    """Cost, gradient and Hessian approximation of the coarse single-shooting OCP.

    Hessian: Gauss-Newton 2 J_r^T J_r of the least-squares cost (eqs. 20a, 21) plus the
    exact curvature of the input map (saturation and the product v d of eq. 18),
    weighted by the adjoint mu_k = dJ / du_k.  Only the curvature of the state
    dynamics (the T^4 radiation terms) is left out; the result may be indefinite,
    which IPOPT corrects.

    Parameters
    ----------
    model : DiscreteModel
    theta0 : (n,) initial state (K)
    dt : interval length (s); n_heun Heun substeps per interval
    T_knots : (K + 1,) T_ref at the knots (K)
    weights : (K,) quadrature weights of knots 1..K
    g0, g1 : weights of eq. (20a)
    inputs : an :class:`InputMap`
    reg : (n_params,) optional weights rho_i of a Tikhonov term sum_i rho_i p_i^2 (K^2)
    check : called at every knot of every sweep and simulation; it raises to end the solve
        (a cancelled or spent :class:`twin.control.budget.PlanBudget`)
    """

    def __init__(self, model: DiscreteDynamics, theta0: Array, dt: float, n_heun: int, T_knots: Array,
                 weights: Array, g0: float, g1: float, inputs: InputMap, reg: Array | None = None,
                 check: Callable[[], None] | None = None) -> None:
        self.model = model
        self.theta0 = np.asarray(theta0, float)
        self.dt = dt
        self.n_heun = n_heun
        self.T_knots = np.asarray(T_knots, float)
        self.weights = np.asarray(weights, float)
        self.g0, self.g1 = g0, g1
        self.map = inputs
        self.reg = np.zeros(inputs.n_params) if reg is None else np.asarray(reg, float)
        self.K = len(self.weights)
        self.c_m = np.asarray(model.c_m, float)
        W = np.asarray(model.W, float)
        self.W = 0.5 * (W + W.T)
        lam, V = np.linalg.eigh(self.W)
        keep = lam > 1e-12 * max(float(lam.max()), 1e-300)
        self.R = np.sqrt(lam[keep])[:, None] * V[:, keep].T  # W = R^T R on its range
        self._check = check or (lambda: None)
        self._cache: OrderedDict[bytes, SweepResult] = OrderedDict()
        self.n_sweeps = 0
        self.n_simulations = 0

    # -- model pieces
    def _f(self, theta: Array, u: Array) -> Array:
        m = self.model
        return (np.asarray(m.step(theta, u), float) - theta) / m.t_s

    def _jacs(self, theta: Array, u: Array) -> tuple[Array, Array]:
        m = self.model
        J = (np.asarray(m.jac_theta(theta, u), float) - np.eye(m.n)) / m.t_s
        B = np.asarray(m.jac_u(theta, u), float) / m.t_s
        return J, B

    def _interval(self, theta: Array, u: Array) -> Array:
        return heun_interval(self.model, theta, u, self.dt, self.n_heun)

    def _interval_jacobians(self, theta: Array, u: Array) -> tuple[Array, list[tuple[Array, ...]]]:
        """theta_k+1 and the Jacobians (J1, B1, J2, B2) of both Heun stages of every substep."""
        h = self.dt / self.n_heun
        stages: list[tuple[Array, ...]] = []
        for _ in range(self.n_heun):
            k1 = self._f(theta, u)
            J1, B1 = self._jacs(theta, u)
            mid = theta + h * k1
            k2 = self._f(mid, u)
            J2, B2 = self._jacs(mid, u)
            theta = theta + 0.5 * h * (k1 + k2)
            stages.append((J1, B1, J2, B2))
        return theta, stages

    def _propagate(self, S: Array, dU: Array, stages: list[tuple[Array, ...]]) -> Array:
        """Forward sensitivity through one interval: dk1 = J1 S + B1 dU, dk2 = J2 (S + h dk1) + B2 dU."""
        h = self.dt / self.n_heun
        for J1, B1, J2, B2 in stages:
            BdU1 = B1 @ dU
            dk1 = J1 @ S + BdU1
            dk2 = J2 @ (S + h * dk1) + B2 @ dU
            S = S + 0.5 * h * (dk1 + dk2)
        return S

    def _adjoint(self, lam: Array, stages: list[tuple[Array, ...]]) -> tuple[Array, Array]:
        """lambda before the interval and mu = dJ/du of the interval's input, from lambda after it."""
        h = self.dt / self.n_heun
        mu = np.zeros(stages[0][1].shape[1])
        for J1, B1, J2, B2 in reversed(stages):
            j2l = J2.T @ lam
            mu = mu + 0.5 * h * (B1.T @ lam + B2.T @ lam + h * (B1.T @ j2l))
            lam = lam + 0.5 * h * (J1.T @ lam + j2l + h * (J1.T @ j2l))
        return lam, mu

    def _stage_cost(self, k: int, theta: Array) -> float:
        e = float(self.c_m @ theta) - self.T_knots[k + 1]
        return float(self.weights[k] * (self.g0 * e * e + self.g1 * theta @ self.W @ theta))

    def _remember(self, key: bytes, result: SweepResult) -> None:
        self._cache[key] = result
        while len(self._cache) > 4:
            self._cache.popitem(last=False)

    # -- evaluations
    def simulate(self, p: Array) -> tuple[float, Array]:
        """Cost and coarse trajectory (K + 1, n) without derivatives."""
        self.n_simulations += 1
        U = self.map.inputs(p)
        theta = self.theta0.copy()
        traj = np.empty((self.K + 1, theta.size))
        traj[0] = theta
        cost = 0.0
        for k in range(self.K):
            self._check()
            theta = self._interval(theta, U[k])
            traj[k + 1] = theta
            cost += self._stage_cost(k, theta)
        return cost + float(self.reg @ (p * p)), traj

    def sweep(self, p: Array) -> SweepResult:
        """Cost, gradient and Hessian approximation at p (cached for the last few p)."""
        key = np.ascontiguousarray(p, float).tobytes()
        hit = self._cache.get(key)
        if hit is not None and hit.grad is not None:
            return hit
        self.n_sweeps += 1
        n, npar, K = self.model.n, self.map.n_params, self.K
        U = self.map.inputs(p)
        theta = self.theta0.copy()
        traj = np.empty((K + 1, n))
        traj[0] = theta
        intervals: list[list[tuple[Array, ...]]] = []
        S = np.zeros((n, npar))
        r_rows = self.R.shape[0]
        Jr = np.zeros((K * (1 + r_rows), npar))
        res = np.zeros(K * (1 + r_rows))
        dJ_dtheta = np.zeros((K + 1, n))
        cost = 0.0
        for k in range(K):
            self._check()
            dU, na = self.map.input_derivatives(p, k)
            theta, stages = self._interval_jacobians(theta, U[k])
            intervals.append(stages)
            S[:, :na] = self._propagate(S[:, :na], dU, stages)
            traj[k + 1] = theta
            sw0 = np.sqrt(self.weights[k] * self.g0)
            sw1 = np.sqrt(self.weights[k] * self.g1)
            row = k * (1 + r_rows)
            e = float(self.c_m @ theta) - self.T_knots[k + 1]
            res[row] = sw0 * e
            Jr[row, :na] = sw0 * (self.c_m @ S[:, :na])
            res[row + 1: row + 1 + r_rows] = sw1 * (self.R @ theta)
            Jr[row + 1: row + 1 + r_rows, :na] = sw1 * (self.R @ S[:, :na])
            dJ_dtheta[k + 1] = 2.0 * self.weights[k] * (self.g0 * e * self.c_m + self.g1 * (self.W @ theta))
            cost += self._stage_cost(k, theta)
        # adjoint: lambda_k = dJ/dtheta_k + (d theta_k+1/d theta_k)^T lambda_k+1,  mu_k = dJ/du_k
        mu = np.empty_like(U)
        lam = dJ_dtheta[K].copy()
        for k in range(K - 1, -1, -1):
            lam, mu[k] = self._adjoint(lam, intervals[k])
            lam = lam + dJ_dtheta[k]
        grad = 2.0 * (Jr.T @ res) + 2.0 * self.reg * p
        hess = 2.0 * (Jr.T @ Jr) + self.map.input_curvature(p, mu)
        hess[np.diag_indices_from(hess)] += 2.0 * self.reg
        cost += float(self.reg @ (p * p))
        out = SweepResult(cost, grad, hess, traj)
        out.mu = mu  # type: ignore[attr-defined]
        self._remember(key, out)
        return out

    def cost(self, p: Array) -> float:
        key = np.ascontiguousarray(p, float).tobytes()
        hit = self._cache.get(key)
        if hit is not None:
            return hit.cost
        c, traj = self.simulate(p)
        self._remember(key, SweepResult(c, None, None, traj))
        return c


# --------------------------------------------------------------------------- CasADi glue
