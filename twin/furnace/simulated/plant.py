"""The simulated furnace: full-order finite-difference model of the specimen (paper section 2.1).

State: the cell temperatures T (N_s = N_x N_y, cell k = i + N_x j) in K.  Each cell stores
the energy rho B_s A h(T) (h the specific enthalpy of ``twin.physics.materials.Steel``), so eq. (1)
integrated over a cell reads

    rho B_s A c_p(T_k) dT_k/dt = Q_cond,k(T) - A (q_r + q_c + q_h)_k,            (1), (2)

with Q_cond the finite-volume conduction including the edge conditions (3a-d)
(:mod:`twin.furnace.simulated.conduction`), q_c + q_h the face losses of eq. (6) (:mod:`twin.physics.boundary`) and
the net radiative flux of eq. (4) from the radiation helper,

    q_r = P1(eta) [T^4; T_w^4] + P2(eta) u_lamp,                                    (4)

where P(eta) interpolates the tabulated positions linearly.  Inputs are group fractions u
(6,) of u_max; lamp fractions are ``cfg.group_matrix @ u`` and the lamp flux at the lamp
surface is ``lamp fraction * lamp_flux_max * (1 + mismatch.lamp_efficiency)`` (W/m^2).
Every lamp is addressable with ``u_lamps=`` (N_h + N_v fractions) instead of ``u``.
Inputs are held over a step (zero-order hold) and clipped to [0, 1] (the thyristors
saturate).

Time integration (:mod:`twin.furnace.simulated.integrators`) is explicit and needs about one
right-hand side per sample by default: the two-step Adams-Bashforth method, started with a Heun
step, its history carried in an explicit :class:`PlantState` (``advance(state, u, dt, eta_of_t)
-> state``).  Measured on small_config, 120 s at full power then 120 s at half power with
oscillation, against RK4 at h = 0.02 s: AB2 at 0.1 s is off by at most 0.056 K, Heun by
0.013 K, RK4 at 0.1 s by 0.002 K; all far below the 1 K TC noise.  The cost is dominated by
the P1 mat-vec (memory bound), hence one evaluation per sample.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> plant = Plant(small_config(), radiation=None)
>>> state = plant.advance(plant.start(np.full(plant.n, 900.0)), np.zeros(6), 1.0, lambda t: 0.0)
>>> state.t, bool(state.T.max() < 900.0)     # without lamps the plate cools
(1.0, True)
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.furnace.simulated import integrators
from twin.furnace.simulated.conduction import ConductionOperator, EdgeExchange
from twin.furnace.simulated.integrators import PlantState
from twin.furnace.simulated.radiative_source import PlantRadiation
from twin.numerics import damped_newton
from twin.physics.boundary import (
    clamped_fraction,
    edge_losses,
    face_loss_coefficients,
    holder_temperature,
    inert_gas_temperature,
)
from twin.physics.fillet import Fillet
from twin.physics.grid import cell_centers, cell_coordinates
from twin.physics.materials import Steel
from twin.physics.motion import hat_weights
from twin.scenario import Mismatch

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

__all__ = ["Plant", "PlantState"]

class Plant:
    """Full-order FD plant, eqs. (1)-(4), (6); see the module docstring.

    Parameters
    ----------
    cfg : FurnaceConfig
    radiation : RadiationModel or None
        From ``twin.radiation.radiation_model(cfg)``; ``None`` switches radiation off
        (conduction, convection and holder losses only).
    mismatch : Mismatch
        Plant deviations from the nominal model: specimen emissivity, alpha_h and alpha_ig,
        lamp efficiency (relative).
    method : {"ab2", "heun", "rk4"}
        Explicit scheme of :meth:`step` (see the module docstring).  "ab2" keeps the last
        sub-step as history; it is used only when a call continues the previous one.
    radiation_dtype : numpy float type
        Precision of the P1 specimen block in :meth:`rhs` / :meth:`step` (float32 by default:
        the mat-vec is memory bound; its rounding, ~1e-7 of the emitted ~1e5 W/m^2, moves a
        steady field by ~1e-4 K).  :meth:`jacobian` and :meth:`steady_state` always use float64.
    """

    def __init__(
        self,
        cfg: FurnaceConfig,
        radiation: Any,
        mismatch: Mismatch | None = None,
        *,
        method: str = "ab2",
        radiation_dtype: type = np.float32,
    ) -> None:
        if method not in integrators.METHODS:
            raise ValueError(f"method must be one of {sorted(integrators.METHODS)}, got {method!r}")
        mismatch = mismatch or Mismatch.model_validate({})
        s = cfg.specimen
        self.cfg = cfg
        self.mismatch = mismatch
        self.method = method
        self.nx, self.ny, self.n = s.nx, s.ny, s.nx * s.ny
        self.steel = Steel.from_config(cfg)
        self.dx, self.dy = s.length / s.nx, s.width / s.ny
        self.area = self.dx * self.dy  # A, plate area of one cell (m^2)
        self.x_centers, self.y_centers = cell_centers(cfg)
        xs, _ = cell_coordinates(cfg)
        self.fillet = Fillet.of(cfg)
        #: cells whose centres lie in the closed fillet (those of T_sup), state order
        self.fillet_mask = self.fillet.mask.ravel()
        self.capacity_factor = s.density * s.thickness * self.area  # C_k = factor * c_p(T_k)  (J/K)
        self._inv_cap = 1.0 / self.capacity_factor

        # --- eqs. (3a-d) and (6): Newton cooling, coefficients scaled by the alpha mismatch ---
        scale = 1.0 + mismatch.alpha
        el = edge_losses(cfg, scale)
        edges = EdgeExchange(
            alpha_x0=el.alpha_x,
            T_x0=el.T_top,
            alpha_xL=el.alpha_x,
            T_xL=el.T_bottom,
            alpha_y=el.alpha_y,
            T_y=inert_gas_temperature(cfg, self.x_centers),
        )
        self.conduction = ConductionOperator.for_plate(cfg, self.steel, edges)
        frac = clamped_fraction(cfg)
        #: face heat-transfer coefficients (W/(m^2 K), both faces) and temperatures (K) per cell, eq. (6)
        self.h_gas = 2.0 * scale * cfg.inert_gas.alpha * (1.0 - frac)
        self.h_holder = 2.0 * scale * cfg.holders.alpha * frac
        self.T_gas = inert_gas_temperature(cfg, xs)
        self.T_holder = holder_temperature(cfg, xs).astype(float)
        # linear face loss A (d T - b) in W per cell, from the module shared with the FE model
        d, b = face_loss_coefficients(cfg, scale)
        self._Ad, self._Ab = self.area * d, self.area * b

        # --- eq. (4): radiation tables (the plant's own, with its emissivity and lamp deviations) ---
        self.radiation = None
        self.source: PlantRadiation | None = None
        self.eta_nodes = np.zeros(1)
        if radiation is not None:
            if mismatch.emissivity != 0.0:
                radiation = radiation.with_specimen_emissivity(s.emissivity * (1.0 + mismatch.emissivity))
            self.radiation = radiation
            self.source = PlantRadiation(cfg, radiation, lamp_scale=1.0 + mismatch.lamp_efficiency,
                                         dtype=radiation_dtype)
            self.eta_nodes = self.source.eta_nodes
        self.n_lamps = cfg.lamps.n_lamps
        self.n_groups = cfg.n_groups
        # static part of the Gershgorin bound: conduction + face losses (W/K) / min capacity (J/K)
        self._cap_min = self.capacity_factor * float(np.min(self.steel.cp_table))
        self._Ad_max = float(self._Ad.max())
        cp_slope = np.abs(np.diff(self.steel.cp_table) / np.diff(self.steel.temperatures))
        self._dcp_rel_max = float(cp_slope.max() / np.min(self.steel.cp_table))  # 1/K

    # ------------------------------------------------------------------ inputs and eta
    def eta_weights(self, eta: float) -> Array:
        """Hat-function weights (n_eta,) of the tabulated positions at eta."""
        return hat_weights(self.eta_nodes, eta)

    def inputs(self, u: ArrayLike | None, u_lamps: ArrayLike | None) -> tuple[Array, bool]:
        """Prepared inputs: the saturated fractions with a trailing 1 (the wall term), and whether they
        address lamps (``u_lamps``) instead of groups (``u``).  The integrators take these."""
        if u_lamps is not None:
            v = np.asarray(u_lamps, float)
            if v.shape != (self.n_lamps,):
                raise ValueError(f"u_lamps must have shape ({self.n_lamps},), got {v.shape}")
            per_lamp = True
        else:
            if u is None:
                raise ValueError("give the group powers u or the lamp powers u_lamps")
            v = np.asarray(u, float)
            if v.shape != (self.n_groups,):
                raise ValueError(f"u must have shape ({self.n_groups},) (group fractions), got {v.shape}")
            per_lamp = False
        v1 = np.empty(v.size + 1)
        v1[-1] = 1.0
        np.minimum(np.maximum(v, 0.0), 1.0, out=v1[:-1])
        return v1, per_lamp

    # ------------------------------------------------------------------ fluxes
    def radiative_flux(
        self, T: ArrayLike, u: ArrayLike | None, eta: float, *, u_lamps: ArrayLike | None = None
    ) -> Array:
        """q_r of eq. (4) in W/m^2 of plate area (N_s,), both faces, positive = the plate loses heat."""
        v1, per_lamp = self.inputs(u, u_lamps)
        if self.source is None:
            return np.zeros(self.n)
        return self.source.flux(np.asarray(T, float), v1, per_lamp, eta)

    def heat_flow(self, T: Array, v1: Array, per_lamp: bool, eta: float, lam: Array | None = None) -> Array:
        """Net heat flow into each cell (W): conduction + edges - A (q_r + q_c + q_h)."""
        Q = self.conduction.heat_flow(T, lam)
        Q -= self._Ad * T
        Q += self._Ab
        if self.source is not None:
            Q -= self.area * self.source.flux(T, v1, per_lamp, eta)
        return Q

    def rate(self, T: Array, v1: Array, per_lamp: bool, eta: float) -> Array:
        """dT/dt (K/s) = heat flow / (rho B_s A c_p(T)), prepared inputs (:meth:`inputs`)."""
        Q = self.heat_flow(T, v1, per_lamp, eta)
        Q /= self.steel.heat_capacity(T)
        Q *= self._inv_cap
        return Q

    def heat_capacity(self, T: ArrayLike) -> Array:
        """C_k(T) = rho B_s A c_p(T_k) in J/K per cell."""
        return self.capacity_factor * self.steel.heat_capacity(T)

    def rhs(self, T: ArrayLike, u: ArrayLike | None, eta: float, *, u_lamps: ArrayLike | None = None) -> Array:
        """dT/dt in K/s (N_s,), eqs. (1)-(4), (6)."""
        Tv = np.asarray(T, float)
        v1, per_lamp = self.inputs(u, u_lamps)
        return self.rate(Tv, v1, per_lamp, eta)

    # ------------------------------------------------------------------ Jacobians
    def radiation_matrices(self, weights: ArrayLike) -> tuple[Array, Array, Array]:
        """Weighted P1 specimen block (N, N), wall flux (N,), P2 per group fraction (N, 6).

        ``weights`` are hat weights (``eta_weights``) or period-averaged weights (eq. 11b).
        """
        if self.source is None:
            return np.zeros((self.n, self.n)), np.zeros(self.n), np.zeros((self.n, self.n_groups))
        return self.source.matrices(weights)

    def heat_jacobian(self, T: ArrayLike, P1s: Array | None) -> Array:
        """d(heat flow)/dT in W/K (N, N) dense, for a given specimen block of P1."""
        Tv = np.asarray(T, float)
        J = self.conduction.jacobian(Tv).toarray()
        J[np.diag_indices(self.n)] -= self._Ad
        if P1s is not None and self.radiation is not None:
            J -= self.area * 4.0 * P1s * (Tv**3)[None, :]
        return J

    def jacobian(self, T: ArrayLike, u: ArrayLike | None, eta: float, *, u_lamps: ArrayLike | None = None) -> Array:
        """Analytic d(rhs)/dT in 1/s (N_s, N_s), dense (the radiation couples all cells)."""
        Tv = np.asarray(T, float)
        v, per_lamp = self.inputs(u, u_lamps)
        P1s = self.radiation_matrices(self.eta_weights(eta))[0] if self.radiation is not None else None
        Q = self.heat_flow(Tv, v, per_lamp, eta)
        C = self.heat_capacity(Tv)
        dC = self.capacity_factor * self.steel.heat_capacity_slope(Tv)
        J = self.heat_jacobian(Tv, P1s) / C[:, None]
        J[np.diag_indices(self.n)] -= Q * dC / C**2
        return J

    def spectral_radius_bound(self, T: Array, dTdt: Array) -> float:
        """Gershgorin bound (1/s) of the Jacobian's spectral radius near state T.

        Row sums of |dQ/dT| / C_min (conduction with the largest lambda and slope, face losses, radiation
        4 A max(T)^3 sum_j |P1_kj| over all positions) plus |dT/dt| max|c_p'| / min c_p.
        """
        tmin, tmax = float(T.min()), float(T.max())
        rho = self.conduction.max_row_sum(tmin, tmax) + self._Ad_max
        if self.source is not None:
            rho += 4.0 * self.area * tmax**3 * self.source.row_sum_max
        rate_max = max(float(dTdt.max()), -float(dTdt.min()))
        return rho / self._cap_min + rate_max * self._dcp_rel_max

    # ------------------------------------------------------------------ integration
    def lamp_heat_flow(self, v1: Array, per_lamp: bool, eta: float) -> Array:
        """Heat flow (W) into each cell from the lamps alone: -A P2(eta) u_lamp."""
        if self.source is None:
            return np.zeros(self.n)
        q = self.source.lamp_flux(v1[:-1], per_lamp, eta)
        q *= -self.area
        return q

    def start(self, T: ArrayLike, t: float = 0.0) -> PlantState:
        """A state at time t (s) with temperatures T (N_s,) K and no integrator history."""
        Tv = np.array(T, dtype=float)
        if Tv.shape != (self.n,):
            raise ValueError(f"T must have shape ({self.n},), got {Tv.shape}")
        return PlantState(T=Tv, t=float(t))

    def advance(
        self,
        state: PlantState,
        u: ArrayLike | None,
        dt: float,
        eta_of_t: Callable[[float], float],
        *,
        u_lamps: ArrayLike | None = None,
        max_substep: float | None = None,
    ) -> PlantState:
        """Integrate from ``state.t`` to ``state.t + dt`` with u held (zero-order hold); the new state.

        Parameters
        ----------
        state : from :meth:`start` or the previous call (carries the integrator's history)
        u : (6,) group fractions of u_max (ignored when ``u_lamps`` is given)
        dt : s
        eta_of_t : specimen position eta(t) in m, evaluated at the stage times
        u_lamps : (N_h + N_v,) lamp fractions, addresses every lamp
        max_substep : optional cap on the sub-step (s); the stability bound always applies
        """
        v, per_lamp = self.inputs(u, u_lamps)
        return integrators.advance(self, state, v, per_lamp, float(dt), eta_of_t, max_substep)

    def step(
        self,
        T: ArrayLike,
        u: ArrayLike | None,
        t0: float,
        dt: float,
        eta_of_t: Callable[[float], float],
        *,
        u_lamps: ArrayLike | None = None,
        max_substep: float | None = None,
    ) -> Array:
        """T (N_s,) K at t0 + dt from T at t0: one :meth:`advance` from a fresh state (no history kept)."""
        return self.advance(self.start(T, t0), u, dt, eta_of_t, u_lamps=u_lamps, max_substep=max_substep).T

    def simulate(
        self,
        T0: ArrayLike,
        u_of_t: Callable[[float], Array],
        eta_of_t: Callable[[float], float],
        t_end: float,
        dt: float,
    ) -> tuple[Array, Array]:
        """March with sample time dt, u held per sample; returns times (n,) and states (n, N_s)."""
        return integrators.simulate(self, T0, u_of_t, eta_of_t, t_end, dt)

    # ------------------------------------------------------------------ steady state
    def steady_state(
        self,
        u: ArrayLike,
        weights: ArrayLike | None = None,
        T_guess: ArrayLike | None = None,
        *,
        tol: float = 1e-8,
        max_iter: int = 60,
    ) -> Array:
        """Solve Q(T) = 0 (dT/dt = 0) with Newton and the analytic Jacobian.

        Parameters
        ----------
        u : (6,) group fractions
        weights : hat weights of the eta positions (default: eta = 0); period-averaged
            weights give the steady state of the time-averaged model (eq. 11).
        T_guess : start (K), default the uniform state that balances the inputs roughly
        tol : K, on the largest Newton update
        """
        v = self.inputs(u, None)[0][:-1]
        w = self.eta_weights(0.0) if weights is None else np.asarray(weights, float)
        P1s, qw, P2G = self.radiation_matrices(w)
        src = self._Ab - self.area * (qw + P2G @ v) if self.radiation is not None else self._Ab.copy()

        def residual(T: Array) -> Array:
            Q = self.conduction.heat_flow(T) - self._Ad * T + src
            if self.radiation is not None:
                Q -= self.area * (P1s @ T**4)
            return Q

        T0 = np.full(self.n, 1000.0) if T_guess is None else np.array(T_guess, float)
        # damp: at most 100 K per iteration, and stay above 0 K
        return damped_newton(residual, lambda T: self.heat_jacobian(T, P1s), T0, tol=tol, max_iter=max_iter,
                             max_step=100.0, floor=1.0, what="steady_state: Newton", error=RuntimeError)

    def steady_sensitivity(self, T: Array, weights: ArrayLike | None = None) -> Array:
        """dT_steady/du (N_s, 6) in K per unit group fraction (implicit function theorem)."""
        w = self.eta_weights(0.0) if weights is None else np.asarray(weights, float)
        P1s, _, P2G = self.radiation_matrices(w)
        J = self.heat_jacobian(T, P1s)
        dQdu = -self.area * P2G
        return -sla.solve(J, dQdu)

    # ------------------------------------------------------------------ helpers
    def fillet_mean(self, T: ArrayLike) -> float:
        """Fillet mean (K): the area integral over Omega_f / its area (:class:`twin.physics.fillet.Fillet`)."""
        return float(self.fillet.mean(T))

    def fillet_inhomogeneity(self, T: ArrayLike, reference: float | None = None) -> float:
        """max over the closed fillet's cells |T - mean| (K); ``reference`` replaces the mean if given."""
        ref = self.fillet.mean(T) if reference is None else reference
        return float(self.fillet.sup(T, ref))

    def field(self, T: ArrayLike) -> Array:
        """The state as an image (N_y, N_x): rows = y, columns = x."""
        return np.asarray(T, float).reshape(self.ny, self.nx)
