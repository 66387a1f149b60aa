"""In-plane heat conduction of the specimen: cell-centred finite volumes (paper eqs. 1 and 3a-d).

The plate 0 < x < L_s, 0 < y < W_s of thickness B_s is split into N_x x N_y equal cells
(cell k = i + N_x j, docs/interfaces.md).  Between two neighbouring cells a and b the heat
flow (W) is

    Q_ab = lambda((T_a + T_b) / 2) * B_s * (face length / centre distance) * (T_b - T_a),

i.e. the divergence term of eq. (1) with the conductivity at the mean face temperature.
At the plate's edges the Robin conditions (3a-d) lambda dT/dn = -alpha (T - T_amb) are
imposed through the edge face (area B_s x cell side).  The edge temperature is eliminated
with the half-cell conduction resistance in series with the film resistance,

    Q_edge = -alpha B_s s / (1 + alpha d / (2 lambda(T_c))) * (T_c - T_amb),

(s the edge length of the cell, d the cell size normal to the edge), which is exact for a
linear profile and keeps the scheme second order.  ``alpha = 0`` gives an insulated edge.

Example
-------
>>> import numpy as np
>>> from twin.config import load_config
>>> from twin.materials import Steel
>>> cfg = load_config()
>>> op = ConductionOperator.for_plate(cfg, Steel.from_config(cfg), edges=EdgeExchange.insulated(cfg))
>>> float(np.abs(op.heat_flow(np.full(442, 900.0))).max())
0.0
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.materials import Steel

Array = NDArray[np.float64]


@dataclass(frozen=True)
class EdgeExchange:
    """Robin data of the four plate edges, eqs. (3a-d).

    Attributes
    ----------
    alpha_x0, alpha_xL : float
        Heat transfer coefficient (W/(m^2 K)) at x = 0 (upper holder, 3a) and x = L_s (3b).
    T_x0, T_xL : float
        Ambient temperature (K) at x = 0 (T_h^up) and x = L_s (T_h^lo).
    alpha_y : float
        Heat transfer coefficient (W/(m^2 K)) at y = 0 and y = W_s (inert gas, 3c-d).
    T_y : ndarray (N_x,)
        Ambient temperature (K) along both y edges, T_ig(x_i) at the cell centres.
    """

    alpha_x0: float
    T_x0: float
    alpha_xL: float
    T_xL: float
    alpha_y: float
    T_y: Array

    @classmethod
    def insulated(cls, cfg: FurnaceConfig) -> EdgeExchange:
        """All four edges adiabatic (for conduction-only checks)."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, np.zeros(cfg.specimen.nx))


class ConductionOperator:
    """Finite-volume conduction with lambda(T) and Robin edges on the N_x x N_y cell grid.

    Parameters
    ----------
    nx, ny : int
        Cells along x and y.
    length, width, thickness : float
        L_s, W_s, B_s (m).
    steel : Steel
        Supplies lambda(T) (W/(m K)) and its slope.
    edges : EdgeExchange
        Robin data of eqs. (3a-d).
    """

    def __init__(
        self,
        nx: int,
        ny: int,
        length: float,
        width: float,
        thickness: float,
        steel: Steel,
        edges: EdgeExchange,
    ) -> None:
        self.nx, self.ny = nx, ny
        self.n = nx * ny
        self.steel = steel
        dx, dy = length / nx, width / ny
        self.dx, self.dy = dx, dy
        k = np.arange(self.n).reshape(ny, nx)
        # interior faces: a -> b with geometric factor B_s * face length / centre distance (m)
        a = np.concatenate([k[:, :-1].ravel(), k[:-1, :].ravel()])
        b = np.concatenate([k[:, 1:].ravel(), k[1:, :].ravel()])
        g = np.concatenate([np.full(ny * (nx - 1), thickness * dy / dx), np.full((ny - 1) * nx, thickness * dx / dy)])
        self._a, self._b, self._g = a, b, g
        # edge faces (corner cells appear twice): cell, alpha B_s s (W/K), alpha d / 2 (W/(m K)), T_amb
        x_i = np.arange(nx)
        e_cell = np.concatenate([k[:, 0], k[:, -1], k[0, :], k[-1, :]])
        alpha = np.concatenate(
            [
                np.full(ny, edges.alpha_x0),
                np.full(ny, edges.alpha_xL),
                np.full(nx, edges.alpha_y),
                np.full(nx, edges.alpha_y),
            ]
        )
        side = np.concatenate([np.full(2 * ny, dy), np.full(2 * nx, dx)])
        depth = np.concatenate([np.full(2 * ny, dx), np.full(2 * nx, dy)])
        t_y = np.asarray(edges.T_y, float)[x_i]
        t_amb = np.concatenate([np.full(ny, edges.T_x0), np.full(ny, edges.T_xL), t_y, t_y])
        keep = alpha > 0.0
        self._e = e_cell[keep]
        self._e_ga = (alpha * thickness * side)[keep]  # alpha B_s s (W/K)
        self._e_r = (alpha * depth / 2.0)[keep]  # alpha d / 2 (W/(m K)); divided by lambda -> 1
        self._e_tamb = t_amb[keep]
        # which edge each kept entry belongs to: 0 = x0 (holder up), 1 = xL (holder lo), 2 = y (gas)
        kind = np.concatenate([np.zeros(ny), np.ones(ny), np.full(2 * nx, 2)]).astype(int)
        self._e_kind = kind[keep]
        self._nf = a.size
        # sparsity pattern of the Jacobian: diagonal + both face directions
        rows = np.concatenate([np.arange(self.n), a, b])
        cols = np.concatenate([np.arange(self.n), b, a])
        self._pattern = (rows, cols)
        # geometry of the Gershgorin bound: 2 sum of face factors per cell (diagonal + off-diagonal)
        self._row_geometry_max = float((2.0 * (np.bincount(a, g, self.n) + np.bincount(b, g, self.n))).max())
        self._edge_ga_max = float(np.bincount(self._e, self._e_ga, self.n).max()) if self._e.size else 0.0

    @classmethod
    def for_plate(cls, cfg: FurnaceConfig, steel: Steel, edges: EdgeExchange) -> ConductionOperator:
        """Operator on the specimen grid of ``cfg`` (N_x x N_y cells)."""
        s = cfg.specimen
        return cls(s.nx, s.ny, s.length, s.width, s.thickness, steel, edges)

    # ---- evaluation ----
    def _lambdas(self, T: Array) -> tuple[Array, Array]:
        """lambda at the faces' mean temperatures and at the edge cells (one interpolation)."""
        tm = 0.5 * (T[self._a] + T[self._b])
        lam = self.steel.conductivity(np.concatenate([tm, T[self._e]]))
        return lam[: self._nf], lam[self._nf :]

    def edge_conductance(self, T: Array) -> Array:
        """Series conductance (W/K) of each kept edge face: alpha B_s s / (1 + alpha d / (2 lambda))."""
        lam_e = self.steel.conductivity(T[self._e])
        return self._e_ga / (1.0 + self._e_r / lam_e)

    def heat_flow(self, T: Array) -> Array:
        """Net conductive heat flow into each cell (W), interior faces plus edges (eqs. 1, 3a-d)."""
        lam_f, lam_e = self._lambdas(T)
        f = lam_f * self._g * (T[self._b] - T[self._a])
        q: Array = np.asarray(np.bincount(self._a, f, self.n) - np.bincount(self._b, f, self.n), float)
        if self._e.size:
            ge = self._e_ga / (1.0 + self._e_r / lam_e)
            q -= np.bincount(self._e, ge * (T[self._e] - self._e_tamb), self.n)
        return q

    def edge_losses(self, T: Array) -> dict[str, float]:
        """Heat lost through the edges (W): 'holder_edges' (3a-b) and 'gas_edges' (3c-d)."""
        if not self._e.size:
            return {"holder_edges": 0.0, "gas_edges": 0.0}
        loss = self.edge_conductance(T) * (T[self._e] - self._e_tamb)
        return {
            "holder_edges": float(loss[self._e_kind < 2].sum()),
            "gas_edges": float(loss[self._e_kind == 2].sum()),
        }

    def jacobian(self, T: Array) -> sp.csr_matrix:
        """d heat_flow / dT (W/K), sparse, including the lambda'(T) terms."""
        lam_f = self.steel.conductivity(0.5 * (T[self._a] + T[self._b]))
        dlam_f = self.steel.conductivity_slope(0.5 * (T[self._a] + T[self._b]))
        dT = T[self._b] - T[self._a]
        # f = lam(Tm) g dT ; df/dT_a = g(-lam + lam'/2 dT), df/dT_b = g(lam + lam'/2 dT)
        dfa = self._g * (-lam_f + 0.5 * dlam_f * dT)
        dfb = self._g * (lam_f + 0.5 * dlam_f * dT)
        # q_a += f, q_b -= f
        diag = np.bincount(self._a, dfa, self.n) - np.bincount(self._b, dfb, self.n)
        if self._e.size:
            Te = T[self._e]
            lam_e = self.steel.conductivity(Te)
            dlam_e = self.steel.conductivity_slope(Te)
            den = 1.0 + self._e_r / lam_e
            ge = self._e_ga / den
            dge = self._e_ga * (self._e_r * dlam_e / lam_e**2) / den**2
            diag -= np.bincount(self._e, ge + dge * (Te - self._e_tamb), self.n)
        rows, cols = self._pattern
        vals = np.concatenate([diag, dfb, -dfa])
        return sp.csr_matrix((vals, (rows, cols)), shape=(self.n, self.n))

    def max_row_sum(self, T: Array) -> float:
        """Upper bound (W/K) of the Gershgorin row sums of :meth:`jacobian` at the state T.

        Uses the largest tabulated lambda and the steepest table slope with the largest
        temperature difference across a face (and between an edge cell and its ambient) of T.
        """
        st = self.steel
        lam_max = float(np.max(st.conductivity_table))
        lam_min = float(np.min(st.conductivity_table))
        slope_max = float(np.max(np.abs(np.diff(st.conductivity_table) / np.diff(st.temperatures))))
        dT_face = float(np.max(np.abs(T[self._b] - T[self._a])))
        bound = self._row_geometry_max * (lam_max + 0.5 * slope_max * dT_face)
        if self._e.size:
            dT_edge = float(np.max(np.abs(T[self._e] - self._e_tamb)))
            bound += self._edge_ga_max * (1.0 + self._e_r.max() * slope_max * dT_edge / lam_min**2)
        return bound
