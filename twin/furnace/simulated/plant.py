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

Time integration is explicit and needs about one right-hand side per sample by default:
the two-step Adams-Bashforth method (``method="ab2"``, started and restarted with a Heun step;
the stored history is rebuilt for the currently held input, so the zero-order-hold switches
cost no accuracy).  Heun's method (``"heun"``, two right-hand sides) and classical RK4
(``"rk4"``, four) are available.  The sub-step comes from a Gershgorin bound of the analytic
Jacobian's spectral radius, so it is stable for any temperature; the rates here are below
~1/s (all eigenvalues real at the steady state, the fastest 0.43/s), so one sub-step per
t_s = 0.1 s.  Measured on small_config, 120 s at full power then 120 s at half power with
oscillation, against RK4 at h = 0.02 s: AB2 at 0.1 s is off by at most 0.056 K, Heun by
0.013 K, RK4 at 0.1 s by 0.002 K; all far below the 1 K TC noise.  The cost is dominated by
the P1 mat-vec (memory bound), hence one evaluation per sample for the plant_rtf >= 200 budget.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> plant = Plant(small_config(), radiation=None)
>>> T = plant.step(np.full(plant.n, 900.0), np.zeros(6), 0.0, 1.0, lambda t: 0.0)
>>> bool(T.max() < 900.0)     # without lamps the plate cools
True
"""

from __future__ import annotations

import bisect
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.furnace.simulated.conduction import ConductionOperator, EdgeExchange
from twin.physics.boundary import (
    clamped_fraction,
    edge_losses,
    face_loss_coefficients,
    holder_temperature,
    inert_gas_temperature,
)
from twin.physics.materials import Steel
from twin.scenario import Mismatch, OscillationSpec

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

# Butcher tableaux of the explicit integrators: (a rows, b, c, stability limit on the
# negative real axis |h lambda|); the limits are the textbook values of each method.
_TABLEAUX: dict[str, tuple[list[list[float]], list[float], list[float], float]] = {
    "rk4": (
        [[], [0.5], [0.0, 0.5], [0.0, 0.0, 1.0]],
        [1 / 6, 1 / 3, 1 / 3, 1 / 6],
        [0.0, 0.5, 0.5, 1.0],
        2.785,
    ),
    "heun": ([[], [1.0]], [0.5, 0.5], [0.0, 1.0], 2.0),
}
_STABILITY_MARGIN = 0.7  # use 70 % of the stability limit (Gershgorin bounds are not tight in T)
_AB2_LIMIT = 1.0  # two-step Adams-Bashforth: stable for -1 < h lambda < 0 on the real axis


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
        if method not in (*_TABLEAUX, "ab2"):
            raise ValueError(f"method must be one of {sorted((*_TABLEAUX, 'ab2'))}, got {method!r}")
        mismatch = mismatch or Mismatch.model_validate({})
        s = cfg.specimen
        self.cfg = cfg
        self.mismatch = mismatch
        self.method = method
        self.nx, self.ny, self.n = s.nx, s.ny, s.nx * s.ny
        self.steel = Steel.from_config(cfg)
        self.dx, self.dy = s.length / s.nx, s.width / s.ny
        self.area = self.dx * self.dy  # A, plate area of one cell (m^2)
        self.x_centers = (np.arange(s.nx) + 0.5) * self.dx
        self.y_centers = (np.arange(s.ny) + 0.5) * self.dy
        xs = np.tile(self.x_centers, s.ny)
        ys = np.repeat(self.y_centers, s.nx)
        x0, x1, y0, y1 = cfg.fillet
        self.fillet_mask = (xs > x0) & (xs < x1) & (ys > y0) & (ys < y1)
        self._cap = s.density * s.thickness * self.area  # C_k = _cap * c_p(T_k)  (J/K)
        self._inv_cap = 1.0 / self._cap

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
        self._h_gas = 2.0 * scale * cfg.inert_gas.alpha * (1.0 - frac)  # W/(m^2 K), both faces
        self._h_holder = 2.0 * scale * cfg.holders.alpha * frac
        self._T_gas = inert_gas_temperature(cfg, xs)
        self._T_holder = holder_temperature(cfg, xs).astype(float)
        # linear face loss A (d T - b) in W per cell, from the module shared with the FE model
        d, b = face_loss_coefficients(cfg, scale)
        self._Ad, self._Ab = self.area * d, self.area * b

        # --- eq. (4): radiation tables ---
        self.radiation = None
        if radiation is not None:
            if mismatch.emissivity != 0.0:
                radiation = radiation.with_specimen_emissivity(s.emissivity * (1.0 + mismatch.emissivity))
            self.radiation = radiation
            n = self.n
            P1 = np.asarray(radiation.P1, float)
            if P1.shape[1] != n or P1.shape[2] < n:
                raise ValueError(f"radiation model P1 has shape {P1.shape}, plant has {n} cells")
            self.eta_nodes = np.asarray(radiation.eta_nodes, float)
            self._P1s = np.ascontiguousarray(P1[:, :, :n])  # (n_eta, N, N)  W/(m^2 K^4)
            # copy for the time stepping (float32 by default: the mat-vec is memory bound and
            # float32 halves the traffic; its rounding, ~0.01 W/m^2 against ~500 W/(m^2 K),
            # is far below the Monte-Carlo noise of P1)
            self._P1s32: NDArray[Any] = self._P1s.astype(radiation_dtype)
            self._rad_dtype = radiation_dtype
            Tw4 = np.asarray(radiation.wall_temperatures, float) ** 4
            self._q_wall = P1[:, :, n:] @ Tw4  # (n_eta, N) W/m^2, walls at known temperature
            flux_max = np.asarray(radiation.lamp_flux_max, float) * (1.0 + mismatch.lamp_efficiency)
            self._P2L = np.ascontiguousarray(np.asarray(radiation.P2, float) * flux_max)  # per lamp fraction
            self._P2G = np.ascontiguousarray(self._P2L @ cfg.group_matrix)  # per group fraction
            # [P2 | q_wall] so that one mat-vec with [v; 1] gives lamps + walls
            self._S_G = np.ascontiguousarray(np.concatenate([self._P2G, self._q_wall[:, :, None]], axis=2))
            self._S_L = np.ascontiguousarray(np.concatenate([self._P2L, self._q_wall[:, :, None]], axis=2))
            self._rad_rowsum_max = float(np.abs(self._P1s).sum(axis=2).max())  # for Gershgorin
        else:
            self.eta_nodes = np.zeros(1)
        self._rho, self._rho_age = math.inf, 0  # cached Gershgorin bound (1/s) and its age (sub-steps)
        self._ab2_history: dict[str, Any] | None = None  # method "ab2": the previous sub-step
        self._eta_list = [float(v) for v in self.eta_nodes]
        self._eta_tol = 1e-9 * max(1.0, self._eta_list[-1] - self._eta_list[0])
        self.n_lamps = cfg.lamps.n_lamps
        self.n_groups = cfg.n_groups
        # static part of the Gershgorin bound: conduction + face losses (W/K) / min capacity (J/K)
        self._cap_min = self._cap * float(np.min(self.steel.cp_table))
        self._Ad_max = float(self._Ad.max())
        cp_slope = np.abs(np.diff(self.steel.cp_table) / np.diff(self.steel.temperatures))
        self._dcp_rel_max = float(cp_slope.max() / np.min(self.steel.cp_table))  # 1/K

    # ------------------------------------------------------------------ inputs and eta
    def _eta_index(self, eta: float) -> tuple[int, float]:
        """Interval k and weight w with P(eta) = (1 - w) P_k + w P_{k+1} (linear interpolation).

        Pure Python on purpose: it runs once per right-hand side, numpy's scalar overhead dominates.
        """
        nodes = self._eta_list
        m = len(nodes)
        if m == 1:
            return 0, 0.0
        if not nodes[0] - self._eta_tol <= eta <= nodes[-1] + self._eta_tol:
            raise ValueError(
                f"eta = {eta:.6g} m lies outside the exchange-factor table [{nodes[0]:g}, {nodes[-1]:g}] m"
            )
        k = min(max(bisect.bisect_right(nodes, eta) - 1, 0), m - 2)
        w = (eta - nodes[k]) / (nodes[k + 1] - nodes[k])
        return k, min(max(w, 0.0), 1.0)

    def eta_weights(self, eta: float) -> Array:
        """Hat-function weights (n_eta,) of the tabulated positions at eta."""
        k, w = self._eta_index(eta)
        out = np.zeros(self.eta_nodes.size)
        out[k] += 1.0 - w
        if w > 0.0:
            out[k + 1] += w
        return out

    def _inputs(self, u: ArrayLike | None, u_lamps: ArrayLike | None) -> tuple[Array, bool]:
        """Saturated inputs augmented with a trailing 1 (the wall term), and whether they are per lamp."""
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
    def _radiative_flux(self, T: Array, v1: Array, per_lamp: bool, eta: float) -> Array:
        """q_r of eq. (4) in W/m^2 (net leaving, both faces); blends two mat-vecs, never builds P(eta).

        ``v1`` = [input fractions; 1].  Between table nodes k and k + 1 the two blocks are
        adjacent in memory, so one (2 N_s x N_s) mat-vec serves both.
        """
        if self.radiation is None:
            return np.zeros(self.n)
        T4 = T * T
        T4 *= T4
        S = self._S_L if per_lamp else self._S_G
        k, w = self._eta_index(eta)
        T4_32: NDArray[Any] = T4.astype(self._rad_dtype)
        if w == 0.0:
            q = S[k] @ v1
            q += self._P1s32[k] @ T4_32
            return q
        n = self.n
        r = S[k : k + 2].reshape(2 * n, -1) @ v1
        r += self._P1s32[k : k + 2].reshape(2 * n, n) @ T4_32
        q = r[:n]
        q *= 1.0 - w
        q += w * r[n:]
        return q

    def radiative_flux(
        self, T: ArrayLike, u: ArrayLike | None, eta: float, *, u_lamps: ArrayLike | None = None
    ) -> Array:
        """q_r of eq. (4) in W/m^2 of plate area (N_s,), both faces, positive = the plate loses heat."""
        v1, per_lamp = self._inputs(u, u_lamps)
        return self._radiative_flux(np.asarray(T, float), v1, per_lamp, eta)

    def _heat(self, T: Array, v1: Array, per_lamp: bool, eta: float, lam: Array | None = None) -> Array:
        """Net heat flow into each cell (W): conduction + edges - A (q_r + q_c + q_h)."""
        Q = self.conduction.heat_flow(T, lam)
        Q -= self._Ad * T
        Q += self._Ab
        if self.radiation is not None:
            Q -= self.area * self._radiative_flux(T, v1, per_lamp, eta)
        return Q

    def _rate(self, T: Array, v1: Array, per_lamp: bool, eta: float) -> Array:
        """dT/dt (K/s) = heat flow / (rho B_s A c_p(T))."""
        Q = self._heat(T, v1, per_lamp, eta)
        Q /= self.steel.heat_capacity(T)
        Q *= self._inv_cap
        return Q

    def heat_capacity(self, T: ArrayLike) -> Array:
        """C_k(T) = rho B_s A c_p(T_k) in J/K per cell."""
        return self._cap * self.steel.heat_capacity(T)

    def stored_energy(self, T: ArrayLike) -> float:
        """Energy content rho B_s A sum_k h(T_k) in J (h from the first table temperature)."""
        return float(self._cap * np.sum(self.steel.enthalpy(np.asarray(T, float))))

    def rhs(self, T: ArrayLike, u: ArrayLike | None, eta: float, *, u_lamps: ArrayLike | None = None) -> Array:
        """dT/dt in K/s (N_s,), eqs. (1)-(4), (6)."""
        Tv = np.asarray(T, float)
        v1, per_lamp = self._inputs(u, u_lamps)
        return self._rate(Tv, v1, per_lamp, eta)

    def flux_terms(
        self, T: ArrayLike, u: ArrayLike | None, eta: float, *, u_lamps: ArrayLike | None = None
    ) -> dict[str, float]:
        """Power balance of the whole plate in W; dE/dt = absorbed - emitted - convective - holder.

        Keys: ``absorbed`` (lamp radiation absorbed, -A sum P2 u_lamp), ``emitted`` (net thermal
        radiation leaving, A sum P1 [T^4; T_w^4]), ``convective`` (inert gas on the faces, eq. 6,
        and through the side edges, 3c-d), ``holder`` (jaw contact, eq. 6, and the end edges,
        3a-b), ``conduction_interior`` (sum of interior face flows, zero up to rounding).
        """
        Tv = np.asarray(T, float)
        v1, per_lamp = self._inputs(u, u_lamps)
        A = self.area
        absorbed = emitted = 0.0
        if self.radiation is not None:
            lamps_only = self._radiative_flux(np.zeros(self.n), v1, per_lamp, eta)
            k, w = self._eta_index(eta)
            wall = (1.0 - w) * self._q_wall[k] + (w * self._q_wall[k + 1] if w > 0.0 else 0.0)
            absorbed = -A * float(np.sum(lamps_only - wall))
            emitted = A * float(np.sum(self._radiative_flux(Tv, v1, per_lamp, eta))) + absorbed
        edges = self.conduction.edge_losses(Tv)
        interior = float(np.sum(self.conduction.heat_flow(Tv))) + edges["holder_edges"] + edges["gas_edges"]
        return {
            "absorbed": absorbed,
            "emitted": emitted,
            "convective": A * float(np.sum(self._h_gas * (Tv - self._T_gas))) + edges["gas_edges"],
            "holder": A * float(np.sum(self._h_holder * (Tv - self._T_holder))) + edges["holder_edges"],
            "conduction_interior": interior,
        }

    # ------------------------------------------------------------------ Jacobians
    def radiation_matrices(self, weights: ArrayLike) -> tuple[Array, Array, Array]:
        """Weighted P1 specimen block (N, N), wall flux (N,), P2 per group fraction (N, 6).

        ``weights`` are hat weights (``eta_weights``) or period-averaged weights (eq. 11b).
        """
        w = np.asarray(weights, float)
        if self.radiation is None:
            return np.zeros((self.n, self.n)), np.zeros(self.n), np.zeros((self.n, self.n_groups))
        return (
            np.tensordot(w, self._P1s, axes=1),
            w @ self._q_wall,
            np.tensordot(w, self._P2G, axes=1),
        )

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
        v, per_lamp = self._inputs(u, u_lamps)
        P1s = self.radiation_matrices(self.eta_weights(eta))[0] if self.radiation is not None else None
        Q = self._heat(Tv, v, per_lamp, eta)
        C = self.heat_capacity(Tv)
        dC = self._cap * self.steel.heat_capacity_slope(Tv)
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
        if self.radiation is not None:
            rho += 4.0 * self.area * tmax**3 * self._rad_rowsum_max
        rate_max = max(float(dTdt.max()), -float(dTdt.min()))
        return rho / self._cap_min + rate_max * self._dcp_rel_max

    # ------------------------------------------------------------------ integration
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
        """Integrate from t0 to t0 + dt with u held constant (zero-order hold).

        Parameters
        ----------
        T : (N_s,) K at t0
        u : (6,) group fractions of u_max (ignored when ``u_lamps`` is given)
        t0, dt : s
        eta_of_t : specimen position eta(t) in m, evaluated at the stage times
        u_lamps : (N_h + N_v,) lamp fractions, addresses every lamp
        max_substep : optional cap on the sub-step (s); the stability bound always applies

        Returns
        -------
        (N_s,) K at t0 + dt
        """
        if dt < 0:
            raise ValueError(f"dt must be >= 0, got {dt}")
        v, per_lamp = self._inputs(u, u_lamps)
        if self.method == "ab2":
            return self._step_ab2(np.array(T, float), v, per_lamp, float(t0), float(dt), eta_of_t, max_substep)
        A, b, c, limit = _TABLEAUX[self.method]
        Tc = np.array(T, float)
        t, t_end = float(t0), float(t0) + float(dt)
        while t_end - t > 1e-12 * max(1.0, abs(t_end)):
            eta0 = eta_of_t(t)
            k1 = self._rate(Tc, v, per_lamp, eta0)
            remaining = t_end - t
            # the Gershgorin bound changes slowly with T: re-evaluate it every 10 sub-steps,
            # or whenever the step would use more than half of the allowed h * rho
            self._rho_age += 1
            if self._rho_age >= 10 or remaining * self._rho > 0.5 * _STABILITY_MARGIN * limit:
                self._rho = self.spectral_radius_bound(Tc, k1)
                self._rho_age = 0
            h_max = _STABILITY_MARGIN * limit / self._rho
            if max_substep is not None:
                h_max = min(h_max, max_substep)
            h = remaining / max(1, math.ceil(remaining / h_max - 1e-9))
            ks = [k1]
            for i in range(1, len(b)):
                Ti = Tc.copy()
                for aij, kj in zip(A[i], ks, strict=False):
                    if aij != 0.0:
                        Ti += (h * aij) * kj
                ks.append(self._rate(Ti, v, per_lamp, eta_of_t(t + c[i] * h)))
            for bi, ki in zip(b, ks, strict=True):
                Tc += (h * bi) * ki
            t += h
        return Tc

    def _lamp_heat(self, v1: Array, per_lamp: bool, eta: float) -> Array:
        """Heat flow (W) into each cell from the lamps alone: -A P2(eta) u_lamp."""
        if self.radiation is None:
            return np.zeros(self.n)
        P2 = self._P2L if per_lamp else self._P2G
        v = v1[:-1]
        k, w = self._eta_index(eta)
        if w == 0.0:
            q = P2[k] @ v
        else:
            r = P2[k : k + 2].reshape(2 * self.n, -1) @ v
            q = r[: self.n]
            q *= 1.0 - w
            q += w * r[self.n :]
        q *= -self.area
        return q

    def _step_ab2(
        self,
        T: Array,
        v1: Array,
        per_lamp: bool,
        t0: float,
        dt: float,
        eta_of_t: Callable[[float], float],
        max_substep: float | None,
    ) -> Array:
        """Two-step Adams-Bashforth with one right-hand side per sub-step (variable step).

        T_{n+1} = T_n + h [(1 + r) f_n - r f_{n-1}], r = h / (2 h_prev).  The history f_{n-1}
        is rebuilt for the *current* inputs: the lamp term (cheap, linear in u) is re-evaluated
        at eta_{n-1}, the rest (conduction, losses, P1 T^4) is stored.  So a change of the held
        input between samples costs no accuracy.  The history is used only when this call
        continues the previous one (same eta function, t0 and T equal to its end); otherwise a
        Heun step starts the method.
        """
        hist = self._ab2_history
        continuing = (
            hist is not None
            and hist["eta_fn"] is eta_of_t
            and abs(hist["t_end"] - t0) <= 1e-9 * max(1.0, abs(t0))
            and np.array_equal(hist["T_end"], T)
        )
        prev = hist["prev"] if continuing and hist is not None else None
        t, t_end = t0, t0 + dt
        while t_end - t > 1e-12 * max(1.0, abs(t_end)):
            eta_n = eta_of_t(t)
            Q = self._heat(T, v1, per_lamp, eta_n)
            QL = self._lamp_heat(v1, per_lamp, eta_n)
            C = self.heat_capacity(T)
            f = Q / C
            remaining = t_end - t
            self._rho_age += 1
            if self._rho_age >= 10 or remaining * self._rho > 0.5 * _STABILITY_MARGIN * _AB2_LIMIT:
                self._rho = self.spectral_radius_bound(T, f)
                self._rho_age = 0
            h_max = _STABILITY_MARGIN * _AB2_LIMIT / self._rho
            if max_substep is not None:
                h_max = min(h_max, max_substep)
            h = remaining / max(1, math.ceil(remaining / h_max - 1e-9))
            if prev is None:  # start with Heun
                T1 = T + h * f
                f1 = self._rate(T1, v1, per_lamp, eta_of_t(t + h))
                T_new = T + (0.5 * h) * (f + f1)
            else:
                Qg_p, C_p, eta_p, h_p, QL_p, v1_p, per_lamp_p = prev
                if per_lamp != per_lamp_p or not np.array_equal(v1, v1_p):  # input changed
                    QL_p = self._lamp_heat(v1, per_lamp, eta_p)
                f_p = (Qg_p + QL_p) / C_p
                r = h / (2.0 * h_p)
                T_new = T + (h * (1.0 + r)) * f - (h * r) * f_p
            prev = (Q - QL, C, eta_n, h, QL, v1, per_lamp)
            T = T_new
            t += h
        self._ab2_history = {"eta_fn": eta_of_t, "t_end": t, "T_end": T.copy(), "prev": prev}
        return T

    def simulate(
        self,
        T0: ArrayLike,
        u_of_t: Callable[[float], Array],
        eta_of_t: Callable[[float], float],
        t_end: float,
        dt: float,
    ) -> tuple[Array, Array]:
        """March with sample time dt, u held per sample; returns times (n,) and states (n, N_s)."""
        n_steps = int(round(t_end / dt))
        ts: Array = np.arange(n_steps + 1, dtype=float) * dt
        out = np.empty((n_steps + 1, self.n))
        out[0] = np.asarray(T0, float)
        for j in range(n_steps):
            out[j + 1] = self.step(out[j], u_of_t(ts[j]), ts[j], dt, eta_of_t)
        return ts, out

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
        v = self._inputs(u, None)[0][:-1]
        w = self.eta_weights(0.0) if weights is None else np.asarray(weights, float)
        P1s, qw, P2G = self.radiation_matrices(w)
        src = self._Ab - self.area * (qw + P2G @ v) if self.radiation is not None else self._Ab.copy()
        T = np.full(self.n, 1000.0) if T_guess is None else np.array(T_guess, float)
        for it in range(max_iter):
            Q = self.conduction.heat_flow(T) - self._Ad * T + src
            if self.radiation is not None:
                Q -= self.area * (P1s @ T**4)
            J = self.heat_jacobian(T, P1s)
            dT = sla.solve(J, -Q)
            # damp: at most 100 K per iteration, and stay above 0 K
            scale = min(1.0, 100.0 / max(float(np.max(np.abs(dT))), 1e-300))
            T = np.maximum(T + scale * dT, 1.0)
            if scale == 1.0 and float(np.max(np.abs(dT))) < tol:
                log.debug("steady_state: converged in %d Newton iterations", it + 1)
                return T
        raise RuntimeError(f"steady_state: Newton did not converge in {max_iter} iterations")

    def steady_sensitivity(self, T: Array, weights: ArrayLike | None = None) -> Array:
        """dT_steady/du (N_s, 6) in K per unit group fraction (implicit function theorem)."""
        w = self.eta_weights(0.0) if weights is None else np.asarray(weights, float)
        P1s, _, P2G = self.radiation_matrices(w)
        J = self.heat_jacobian(T, P1s)
        dQdu = -self.area * P2G
        return -sla.solve(J, dQdu)

    # ------------------------------------------------------------------ helpers
    def fillet_mean(self, T: ArrayLike) -> float:
        """Mean temperature (K) of the cells in the fillet Omega_f (equal cell areas)."""
        return float(np.mean(np.asarray(T)[self.fillet_mask]))

    def fillet_inhomogeneity(self, T: ArrayLike, reference: float | None = None) -> float:
        """max over the fillet |T - mean| (K); ``reference`` replaces the mean if given."""
        Tf = np.asarray(T)[self.fillet_mask]
        ref = float(np.mean(Tf)) if reference is None else reference
        return float(np.max(np.abs(Tf - ref)))

    def field(self, T: ArrayLike) -> Array:
        """The state as an image (N_y, N_x): rows = y, columns = x."""
        return np.asarray(T, float).reshape(self.ny, self.nx)


def sinusoidal_eta(spec: OscillationSpec) -> Callable[[float], float]:
    """eta(t) = a sin(2 pi t / Pi) if enabled, else 0 (see ``twin.physics.motion.eta_function``)."""
    from twin.physics.motion import eta_function

    return eta_function(spec)


def plant_rtf(cfg: FurnaceConfig, radiation: Any, duration: float = 240.0) -> float:
    """Simulated seconds per wall second of the open-loop plant with oscillation (bench figure).

    The paper's run: eta = 3 L_h sin(2 pi t / 18 s) (capped at eta_max), all six groups at
    0.6 u_max, cold start, one ``step`` per sample t_s.
    """
    plant = Plant(cfg, radiation)
    amplitude = min(3.0 * cfg.lamps.horizontal.pitch, cfg.oscillation.eta_max)
    eta = sinusoidal_eta(OscillationSpec(enabled=True, amplitude=amplitude, period=18.0))
    u = np.full(cfg.n_groups, 0.6)
    t_s = cfg.sampling.t_s
    T = np.full(plant.n, cfg.specimen.initial_temperature)
    for j in range(5):  # warm-up (first calls allocate)
        T = plant.step(T, u, j * t_s, t_s, eta)
    T = np.full(plant.n, cfg.specimen.initial_temperature)
    n_steps = int(round(duration / t_s))
    t0 = time.perf_counter()
    for j in range(n_steps):
        T = plant.step(T, u, j * t_s, t_s, eta)
    wall = time.perf_counter() - t0
    log.info("plant_rtf: %d steps in %.3f s, final fillet mean %.1f K", n_steps, wall, plant.fillet_mean(T))
    return duration / wall
