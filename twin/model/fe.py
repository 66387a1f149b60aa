"""Reduced-order FE model of the specimen: mesh, hat functions and the constant matrices (eqs. 7-10).

The trial functions are tensor products of 1D piecewise-linear hat functions on the
non-uniform node lines ``cfg.fe.x_nodes`` x ``cfg.fe.y_nodes`` (relative, times L_s, W_s),
phi_k(x, y) = h_i(x) g_j(y) with k = i + n_x j (the same ordering as the FD cells).
Every integral below is a tensor product of 1D integrals of piecewise polynomials and is
evaluated exactly (Gauss-Legendre on the pieces between node lines and cell faces).

Model (9), per unit thickness::

    rho M theta' = K theta + chi(theta, u, eta) + gamma(theta)

* M = int c_p phi phi^T dOmega with the constant, enthalpy-equivalent c_p over
  ``fe.capacity_range`` (J/(kg K) m^2),
* K = -int lambda grad phi . grad phi^T dOmega with lambda at ``fe.reference_temperature``,
* gamma(theta) = -Gamma theta + gamma_0 from the edge conditions (3a-d),
* chi = -(1/B_s) G^T (q_r + q_c + q_h) (eq. 10) with G = int H phi^T dOmega (N_s x N~),
  T = M_theta theta at the FD cell centres.

Example
-------
>>> from twin.config import load_config
>>> fe = FEModel(load_config())
>>> fe.n, fe.M_theta.shape
(105, (442, 105))
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.physics.boundary import edge_losses, inert_gas_temperature
from twin.physics.fillet import Fillet, fillet_box
from twin.physics.grid import cell_centers
from twin.physics.materials import Steel

Array = NDArray[np.float64]

_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(3)  # exact up to degree 5 per piece


def hat_functions(nodes: Array, x: ArrayLike) -> Array:
    """1D hat functions h_i(x) on ``nodes`` (m), shape (len(x), len(nodes)); zero outside."""
    xv = np.atleast_1d(np.asarray(x, float))
    eye = np.eye(len(nodes))
    out = np.stack([np.interp(xv, nodes, eye[i], left=0.0, right=0.0) for i in range(len(nodes))], axis=1)
    return out


def hat_derivatives(nodes: Array, x: ArrayLike) -> Array:
    """d h_i / dx (1/m) at x (inside an element), shape (len(x), len(nodes))."""
    xv = np.atleast_1d(np.asarray(x, float))
    e = np.clip(np.searchsorted(nodes, xv, side="right") - 1, 0, len(nodes) - 2)
    h = nodes[e + 1] - nodes[e]
    out = np.zeros((len(xv), len(nodes)))
    rows = np.arange(len(xv))
    out[rows, e] = -1.0 / h
    out[rows, e + 1] = 1.0 / h
    return out


def quadrature(nodes: Array, a: float, b: float) -> tuple[Array, Array]:
    """Gauss points and weights on [a, b], split at the node lines; exact for piecewise quintics."""
    cuts = np.unique(np.concatenate([[a, b], nodes[(nodes > a) & (nodes < b)]]))
    lo, hi = cuts[:-1], cuts[1:]
    half = 0.5 * (hi - lo)
    xq = (0.5 * (hi + lo))[:, None] + half[:, None] * _GAUSS_X[None, :]
    wq = half[:, None] * _GAUSS_W[None, :]
    return xq.ravel(), wq.ravel()


def hat_integrals(nodes: Array, a: float, b: float) -> Array:
    """int_a^b h_i(x) dx for every node i (m), shape (len(nodes),)."""
    xq, wq = quadrature(nodes, a, b)
    return wq @ hat_functions(nodes, xq)


def hat_gram(nodes: Array, a: float, b: float, derivative: bool = False) -> Array:
    """int_a^b h_i h_j dx (m), or int_a^b h_i' h_j' dx (1/m) if ``derivative``; (N, N)."""
    xq, wq = quadrature(nodes, a, b)
    v = hat_derivatives(nodes, xq) if derivative else hat_functions(nodes, xq)
    return (v * wq[:, None]).T @ v


def cell_integrals(nodes: Array, length: float, n_cells: int) -> Array:
    """int over FD cell i of h_a(x) dx, shape (n_cells, len(nodes)) (1D factor of G)."""
    edges = np.linspace(0.0, length, n_cells + 1)
    return np.stack([hat_integrals(nodes, edges[i], edges[i + 1]) for i in range(n_cells)])


class FEModel:
    """Tensor-product P1 (bilinear) FE discretisation of the specimen (paper section 2.2).

    Parameters
    ----------
    cfg : furnace configuration; uses ``specimen``, ``material``, ``fe``, ``holders``,
        ``inert_gas``.

    Attributes
    ----------
    x_nodes, y_nodes : node lines in m
    n : number of nodes N~
    """

    def __init__(self, cfg: FurnaceConfig) -> None:
        s = cfg.specimen
        self.cfg = cfg
        self.x_nodes = np.asarray(cfg.fe.x_nodes, float) * s.length
        self.y_nodes = np.asarray(cfg.fe.y_nodes, float) * s.width
        self.nx_nodes = len(self.x_nodes)
        self.ny_nodes = len(self.y_nodes)
        self.n = self.nx_nodes * self.ny_nodes
        steel = Steel.from_config(cfg)
        self.density = s.density
        self.heat_capacity = steel.mean_heat_capacity(*cfg.fe.capacity_range)
        self.conductivity = float(steel.conductivity(cfg.fe.reference_temperature))

    # ---- trial functions (7) ----
    def phi(self, points: ArrayLike) -> Array:
        """phi^T at absolute points (n, 2) in m -> (n, N~); row i is phi(xi_i)^T."""
        p = np.atleast_2d(np.asarray(points, float))
        hx = hat_functions(self.x_nodes, p[:, 0])
        hy = hat_functions(self.y_nodes, p[:, 1])
        return (hy[:, :, None] * hx[:, None, :]).reshape(len(p), self.n)

    def C(self, points: ArrayLike) -> Array:
        """Output matrix of eq. (12b): rows phi(xi_i)^T for the TC positions (m)."""
        return self.phi(points)

    def nodes(self) -> Array:
        """Node coordinates (N~, 2) in m, order k = i + n_x j."""
        X, Y = np.meshgrid(self.x_nodes, self.y_nodes)
        return np.column_stack([X.ravel(), Y.ravel()])

    # ---- 1D building blocks ----
    @cached_property
    def _mass_x(self) -> Array:
        return hat_gram(self.x_nodes, 0.0, self.x_nodes[-1])

    @cached_property
    def _mass_y(self) -> Array:
        return hat_gram(self.y_nodes, 0.0, self.y_nodes[-1])

    # ---- constant matrices of (9) ----
    @cached_property
    def M(self) -> Array:
        """Heat capacity matrix int c_p phi phi^T dOmega in J/(kg K) m^2 (eq. 9, constant c_p)."""
        return np.asarray(self.heat_capacity * np.kron(self._mass_y, self._mass_x), float)

    @cached_property
    def K(self) -> Array:
        """Conductivity matrix -int lambda grad phi grad phi^T dOmega in W/K (eq. 9)."""
        kx = hat_gram(self.x_nodes, 0.0, self.x_nodes[-1], derivative=True)
        ky = hat_gram(self.y_nodes, 0.0, self.y_nodes[-1], derivative=True)
        return -self.conductivity * (np.kron(self._mass_y, kx) + np.kron(ky, self._mass_x))

    @cached_property
    def M_theta(self) -> Array:
        """T = M_theta theta at the FD cell centres, (N_s, N~) (section 2.2, after eq. 10)."""
        xc, yc = cell_centers(self.cfg)
        X, Y = np.meshgrid(xc, yc)
        return self.phi(np.column_stack([X.ravel(), Y.ravel()]))

    @cached_property
    def G(self) -> Array:
        """G = int H phi^T dOmega in m^2, (N_s, N~): chi = -(1/B_s) G^T q (eq. 10)."""
        s = self.cfg.specimen
        gx = cell_integrals(self.x_nodes, s.length, s.nx)
        gy = cell_integrals(self.y_nodes, s.width, s.ny)
        return np.asarray(np.kron(gy, gx), float)

    @cached_property
    def _edge_terms(self) -> tuple[Array, Array]:
        s = self.cfg.specimen
        e = edge_losses(self.cfg)
        nx, ny = self.nx_nodes, self.ny_nodes
        first_x, last_x = np.eye(nx)[0], np.eye(nx)[-1]
        first_y, last_y = np.eye(ny)[0], np.eye(ny)[-1]
        # x = 0 and x = L_s edges (3a-b): alpha_h int phi_k (T - T_h) dy
        gamma = e.alpha_x * np.kron(self._mass_y, np.outer(first_x, first_x) + np.outer(last_x, last_x))
        int_y = hat_integrals(self.y_nodes, 0.0, s.width)
        g0 = e.alpha_x * np.kron(int_y, e.T_top * first_x + e.T_bottom * last_x)
        # y = 0 and y = W_s edges (3c-d): alpha_ig int phi_k (T - T_ig(x)) dx
        gamma = gamma + e.alpha_y * np.kron(np.outer(first_y, first_y) + np.outer(last_y, last_y), self._mass_x)
        xq, wq = quadrature(self.x_nodes, 0.0, s.length)
        int_tig = (wq * inert_gas_temperature(self.cfg, xq)) @ hat_functions(self.x_nodes, xq)
        g0 = g0 + e.alpha_y * np.kron(first_y + last_y, int_tig)
        return gamma, g0

    @property
    def Gamma(self) -> Array:
        """Edge-loss matrix in W/K: gamma(theta) = -Gamma theta + gamma_0 (eqs. 3a-d in 8)."""
        return self._edge_terms[0]

    @property
    def gamma0(self) -> Array:
        """Constant part of gamma in W (per unit thickness, i.e. W/m times m)."""
        return self._edge_terms[1]

    def gamma(self, theta: ArrayLike) -> Array:
        """Boundary vector gamma(theta) of eq. (9) from (3a-d)."""
        return -self.Gamma @ np.asarray(theta, float) + self.gamma0

    # ---- fillet quantities (19), (21) ----
    @cached_property
    def _fillet_factors(self) -> tuple[Array, Array, Array, Array, float]:
        x0, x1, y0, y1 = fillet_box(self.cfg.specimen.length, self.cfg.specimen.width)
        area = (x1 - x0) * (y1 - y0)
        return (
            hat_integrals(self.x_nodes, x0, x1),
            hat_integrals(self.y_nodes, y0, y1),
            hat_gram(self.x_nodes, x0, x1),
            hat_gram(self.y_nodes, y0, y1),
            area,
        )

    @cached_property
    def c_m_exact(self) -> Array:
        """Eq. (19) as written: c = int_{Omega_f} phi dOmega / A_f, (N~,), the exact mean of the FE field."""
        cx, cy, _, _, area = self._fillet_factors
        return np.asarray(np.kron(cy, cx) / area, float)

    @cached_property
    def c_m(self) -> Array:
        """Fillet mean weights (N~,): c_m^T theta is the fillet mean of the model's field on the FD cells.

        c_m = M_theta^T a with a the cell area weights of :class:`twin.physics.fillet.Fillet`, so the
        estimated mean is the same functional the metrics apply to the true field (product.md).  It
        differs from eq. (19) integrated exactly (:attr:`c_m_exact`) only by the cell quadrature
        of the bilinear FE field.
        """
        return np.asarray(self.M_theta.T @ Fillet.of(self.cfg).flat_weights, float)

    @cached_property
    def W(self) -> Array:
        """Inhomogeneity matrix W = int_{Omega_f} phi phi^T dOmega / A_f - c c^T (eq. 21), c exact (19).

        theta^T W theta is the variance of the FE field over the fillet (W 1 = 0).
        """
        _, _, wx, wy, area = self._fillet_factors
        return np.kron(wy, wx) / area - np.outer(self.c_m_exact, self.c_m_exact)

    # ---- evaluation helpers ----
    def fillet_mean(self, theta: ArrayLike) -> float:
        """T~ = c_m^T theta in K (eq. 19 on the FD cells, see :attr:`c_m`)."""
        return float(self.c_m @ np.asarray(theta, float))

    @cached_property
    def _cell_hats(self) -> tuple[Array, Array]:
        """1D hats at the cell centres, (N_y, n_y nodes) and (n_x nodes, N_x): M_theta = kron(H_y, H_x^T)."""
        xc, yc = cell_centers(self.cfg)
        return hat_functions(self.y_nodes, yc), np.ascontiguousarray(hat_functions(self.x_nodes, xc).T)

    def field_on_cells(self, theta: ArrayLike) -> Array:
        """Temperature at the FD cell centres as an image (N_y, N_x) in K, = (M_theta theta) reshaped.

        Uses the tensor structure of the hats (two small products instead of M_theta, whose
        dense or sparse product costs 3-10 times as much per call); the closed loop calls this
        at every sample.
        """
        hy, hxT = self._cell_hats
        return hy @ (np.asarray(theta, float).reshape(self.ny_nodes, self.nx_nodes) @ hxT)
