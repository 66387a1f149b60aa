"""A small stand-in for ``twin.model.discrete.DiscreteModel`` used only by the controller tests.

A plate of ``nx x ny`` nodes with conduction to its neighbours, two-sided radiation
to cold walls (the T^4 nonlinearity of eq. 4) and ``m`` heater groups with smooth
spatial footprints, discretized by forward Euler like eq. (12a):

    theta+ = theta + t_s (A_c theta - k_r (theta^4 - T_w^4) + B u)

It has the attributes of the DiscreteModel contract (docs/interfaces.md): n, m, t_s,
c_m, W, step, jac_theta, jac_u, casadi_step.  Its numbers are test inputs chosen to
give furnace-like magnitudes (steady state around 1100 K at about half power, mean
time constant of some ten seconds); they are not furnace parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

SIGMA = 5.670374419e-8


@dataclass
class StandInModel:
    n: int
    m: int
    t_s: float
    c_m: np.ndarray
    W: np.ndarray
    A_c: np.ndarray
    B: np.ndarray
    k_r: np.ndarray
    T_w: float

    def rhs(self, theta, u):
        return self.A_c @ theta - self.k_r * (theta**4 - self.T_w**4) + self.B @ u

    def step(self, theta, u):
        theta = np.asarray(theta, float)
        return theta + self.t_s * self.rhs(theta, np.asarray(u, float))

    def jac_theta(self, theta, u):
        theta = np.asarray(theta, float)
        return np.eye(self.n) + self.t_s * (self.A_c - np.diag(4.0 * self.k_r * theta**3))

    def jac_u(self, theta, u):
        return self.t_s * self.B

    def casadi_step(self):
        th = ca.MX.sym("theta", self.n)
        u = ca.MX.sym("u", self.m)
        rhs = ca.mtimes(ca.DM(self.A_c), th) - ca.DM(self.k_r) * (th**4 - self.T_w**4) + ca.mtimes(ca.DM(self.B), u)
        return ca.Function("F", [th, u], [th + self.t_s * rhs], ["theta", "u"], ["theta_next"])


def make_standin(nx: int = 6, ny: int = 4, m: int = 3, t_s: float = 0.1, gain_scale: float = 1.0,
                 emissivity: float = 0.9) -> StandInModel:
    """Build the stand-in plate; ``gain_scale`` scales B (plant mismatch in the tests)."""
    n = nx * ny
    xs = (np.arange(nx) + 0.5) / nx
    ys = (np.arange(ny) + 0.5) / ny
    X, Y = np.meshgrid(xs, ys)  # node k = i + nx * j
    x, y = X.ravel(), Y.ravel()
    rho_c_b = 7850.0 * 600.0 * 0.001  # J/(m^2 K): steel plate of 1 mm
    # conduction: graph Laplacian scaled to lambda B / (rho c B h^2) with h = 0.4 m / nx
    h = 0.4 / nx
    coup = 30.0 * 0.001 / h**2 / rho_c_b  # 1/s
    L = np.zeros((n, n))
    for j in range(ny):
        for i in range(nx):
            k = i + nx * j
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                ii, jj = i + di, j + dj
                if 0 <= ii < nx and 0 <= jj < ny:
                    L[k, ii + nx * jj] += coup
                    L[k, k] -= coup
    k_r = np.full(n, 2.0 * emissivity * SIGMA / rho_c_b)
    # heater footprints: Gaussian bumps along x, spread in y; together ~2x the loss at 1100 K
    centres = np.linspace(0.15, 0.85, m)
    B = np.zeros((n, m))
    for g, c in enumerate(centres):
        B[:, g] = np.exp(-((x - c) ** 2) / (2 * 0.15**2)) * (1.0 - 0.3 * (y - 0.5) ** 2)
    loss_1100 = float(k_r[0] * (1100.0**4 - 330.0**4))
    B *= gain_scale * 2.0 * loss_1100 / B.sum(axis=1).mean()
    fillet = (x > 0.25) & (x < 0.75) & (y > 0.2) & (y < 0.8)
    c_m = fillet / fillet.sum()
    S = np.diag(fillet.astype(float)) / fillet.sum()
    W = S - np.outer(c_m, c_m)
    return StandInModel(n, m, t_s, c_m.astype(float), W, L, B, k_r, 330.0)
