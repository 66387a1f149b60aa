"""Discrete-time reduced-order model theta_{j+1} = F(theta_j, u_j) (paper eqs. 9-12a).

Forward Euler (12a) on the (time-averaged, 11) FE model (9)::

    F(theta, u) = theta + t_s f(theta, u),
    f = (rho M)^{-1} (K theta + chi_av(theta, u) + gamma(theta))
      = L theta + A (M_theta theta)^4 + B u + c

with u the 6 group fractions (0..1 of u_max) and, from eq. (10) with T = M_theta theta,
q_r = P1 [T^4; T_w^4] + P2 diag(u_max) G_lamps u (eq. 4), q_c + q_h = d T - b (eq. 6):

    L = (rho M)^{-1} (K - Gamma - G^T diag(d) M_theta / B_s)
    A = -(rho M)^{-1} G^T P1_av[:, :N_s] / B_s
    B = -(rho M)^{-1} G^T P2_av diag(u_max) G_lamps / B_s
    c = (rho M)^{-1} (gamma_0 - G^T (P1_av[:, N_s:] T_w^4 - b) / B_s).

So F is affine in u, and dF/dtheta = I + t_s (L + A diag(4 T^3) M_theta) (16), exactly.

Example
-------
>>> from twin.config import small_config
>>> from twin.radiation import radiation_model
>>> model = discrete_model(small_config(), radiation_model(small_config()), None)
>>> model.step(300.0 * np.ones(model.n), np.full(6, 0.5)).shape
(105,)
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.model.fe import FEModel
from twin.model.tables import ModelTables, Parameters, RadiationLike, model_tables
from twin.numerics import damped_newton
from twin.physics.motion import average_weights
from twin.scenario import OscillationSpec

log = logging.getLogger(__name__)
Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class DiscreteModel:
    """theta_{j+1} = F(theta_j, u_j) of eq. (12a); see the module docstring for L, A, B, c.

    Attributes
    ----------
    fe : the FE discretisation (phi, c_m, W, M_theta, ...)
    t_s : sampling time in s
    L : (n, n) 1/s;  A : (n, N_s) 1/(s K^3);  B : (n, m) K/s;  c : (n,) K/s
    oscillation : the oscillation the radiation was averaged over (None = fixed, eta = 0)
    """

    fe: FEModel
    t_s: float
    L: Array
    A: Array
    B: Array
    c: Array
    oscillation: OscillationSpec | None
    _mt_sparse: scipy.sparse.csr_matrix = field(init=False, repr=False)
    _A_T: Array = field(init=False, repr=False)
    _I_tsL: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        # per-sample EKF work (jac_theta) on precomputed pieces: M_theta has ~4 entries per row
        object.__setattr__(self, "_mt_sparse", scipy.sparse.csr_matrix(self.fe.M_theta.T))
        object.__setattr__(self, "_A_T", np.ascontiguousarray(self.A.T))
        object.__setattr__(self, "_I_tsL", np.eye(self.fe.n) + self.t_s * self.L)

    @property
    def n(self) -> int:
        return self.fe.n

    @property
    def m(self) -> int:
        return int(self.B.shape[1])

    @property
    def c_m(self) -> Array:
        return self.fe.c_m

    @property
    def W(self) -> Array:
        return self.fe.W

    @property
    def M_theta(self) -> Array:
        return self.fe.M_theta

    def rhs(self, theta: ArrayLike, u: ArrayLike) -> Array:
        """f(theta, u) = d theta / dt in K/s (eq. 11a)."""
        th = np.asarray(theta, float)
        T = self.fe.field_on_cells(th).ravel()  # M_theta theta
        return self.L @ th + self.A @ (T * T) ** 2 + self.B @ np.asarray(u, float) + self.c

    def step(self, theta: ArrayLike, u: ArrayLike) -> Array:
        """F(theta, u) = theta + t_s f(theta, u) (eq. 12a), u = group fractions (m,)."""
        th = np.asarray(theta, float)
        return th + self.t_s * self.rhs(th, u)

    def jac_theta(self, theta: ArrayLike, u: ArrayLike | None = None) -> Array:
        """dF/dtheta (n, n) = I + t_s (L + A diag(4 T^3) M_theta) (eq. 16); independent of u."""
        T = self.fe.field_on_cells(theta).ravel()  # M_theta theta
        scaled_T = self._A_T * (4.0 * self.t_s * T**3)[:, None]  # (N_s, n): t_s diag(4T^3) A^T
        rad_T = self._mt_sparse @ scaled_T  # t_s M_theta^T diag(4T^3) A^T = (t_s A diag(4T^3) M_theta)^T
        return self._I_tsL + rad_T.T

    def jac_u(self, theta: ArrayLike | None = None, u: ArrayLike | None = None) -> Array:
        """dF/du (n, m) = t_s B (F is affine in u) in K per unit group fraction."""
        return self.t_s * self.B

    def casadi_step(self, kind: str = "MX") -> Any:
        """``casadi.Function("F", [theta, u], [theta_next])`` of eq. (12a), MX (default) or SX."""
        import casadi as ca

        sym: Any = ca.MX if kind == "MX" else ca.SX
        theta: Any = sym.sym("theta", self.n)
        u: Any = sym.sym("u", self.m)
        T: Any = ca.mtimes(ca.DM(scipy.sparse.csc_matrix(self.fe.M_theta)), theta)
        T2 = T * T
        f = (
            ca.mtimes(ca.DM(self.L), theta)
            + ca.mtimes(ca.DM(self.A), T2 * T2)
            + ca.mtimes(ca.DM(self.B), u)
            + ca.DM(self.c)
        )
        return ca.Function("F", [theta, u], [theta + self.t_s * f], ["theta", "u"], ["theta_next"])

    def steady_state(self, u: ArrayLike, theta0: ArrayLike | None = None) -> Array:
        """theta with f(theta, u) = 0 (Newton on the continuous-time model), K."""
        uu = np.asarray(u, float)
        th = np.full(self.n, 1000.0) if theta0 is None else np.asarray(theta0, float)
        eye = np.eye(self.n)
        return damped_newton(lambda x: self.rhs(x, uu), lambda x: (self.jac_theta(x) - eye) / self.t_s, th,
                             tol=1e-9, max_iter=100, what="steady_state: Newton", error=RuntimeError)

    def hold_powers(self, T_mean: float, distribution: ArrayLike | None = None) -> Array:
        """Group fractions u = s * distribution whose steady state has the fillet mean c_m^T theta = T_mean.

        Newton on the scalar s with d(mean)/ds = -c_m^T (df/dtheta)^{-1} B distribution.  Raises
        ``ValueError`` if that needs more than u_max in some group.
        """
        d = np.ones(self.m) if distribution is None else np.asarray(distribution, float)
        s, th = 0.5 / float(d.max()), None
        for _ in range(50):
            th = self.steady_state(s * d, th)
            err = float(self.c_m @ th) - T_mean
            if abs(err) < 1e-8:
                return s * d
            Jc = (self.jac_theta(th) - np.eye(self.n)) / self.t_s
            s -= err / float(self.c_m @ np.linalg.solve(Jc, -self.B @ d))
            if s * float(d.max()) > 1.0:
                raise ValueError(f"T_mean = {T_mean} K needs more than u_max with this distribution")
        raise RuntimeError("hold_powers: Newton did not converge")


def discrete_model(
    cfg: FurnaceConfig,
    radiation: RadiationLike,
    oscillation: OscillationSpec | None = None,
    fe: FEModel | None = None,
    *,
    tables: ModelTables | None = None,
    parameters: Parameters | None = None,
) -> DiscreteModel:
    """Build the discrete-time model (12a), time averaged (11) if ``oscillation`` is enabled.

    Parameters
    ----------
    cfg : furnace configuration (FE grid, t_s, boundary data, lamp groups)
    radiation : the twin's radiation model (P1, P2 at the eta positions)
    oscillation : eta(t) = amplitude sin(2 pi t / period); None or disabled = fixed at eta = 0
    fe : a prebuilt :class:`FEModel` of the same cfg to reuse (optional)
    tables : prebuilt per-position terms (:func:`twin.model.tables.model_tables`) to reuse (optional)
    parameters : calibrated deviations (lamp efficiency, emissivity, convection) of the model
    """
    tables = model_tables(cfg, radiation, fe) if tables is None else tables
    L, A, B, c = tables.terms(average_weights(tables.eta_nodes, oscillation), parameters)
    log.debug("discrete_model: n=%d, oscillation=%s, parameters=%s", tables.n, oscillation, parameters)
    return DiscreteModel(fe=tables.fe, t_s=tables.t_s, L=L, A=A, B=B, c=c, oscillation=oscillation)
