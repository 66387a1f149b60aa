"""In-plane heat conduction of the specimen: cell-centred finite volumes (paper eqs. 1 and 3a-d).

The plate 0 < x < L_s, 0 < y < W_s of thickness B_s is split into N_x x N_y equal cells
(cell k = i + N_x j, docs/interfaces.md).  Between two neighbouring cells a and b the heat
flow (W) is

    Q_ab = (lambda(T_a) + lambda(T_b)) / 2 * B_s * (face length / centre distance) * (T_b - T_a),

i.e. the divergence term of eq. (1) with the mean of the two cells' conductivities at the
face (equal to lambda at the mean face temperature wherever the lambda table is linear,
so second order either way; it needs lambda only at the N_s cells).
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
>>> from twin.physics.materials import Steel
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
from twin.physics.materials import Steel

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
        # geometric factors B_s * face length / centre distance (m), halved for the mean of
        # the two cells' conductivities
        self._gx2 = 0.5 * thickness * dy / dx
        self._gy2 = 0.5 * thickness * dx / dy
        k = np.arange(self.n).reshape(ny, nx)
        # interior faces a -> b (index form, for the Jacobian)
        a = np.concatenate([k[:, :-1].ravel(), k[:-1, :].ravel()])
        b = np.concatenate([k[:, 1:].ravel(), k[1:, :].ravel()])
        g = np.concatenate([np.full(ny * (nx - 1), 2 * self._gx2), np.full((ny - 1) * nx, 2 * self._gy2)])
        self._a, self._b, self._g = a, b, g
        # edges, one entry per side: x = 0, x = L_s (columns), y = 0, y = W_s (rows)
        t_y = np.asarray(edges.T_y, float)
        sides = (
            (k[:, 0], edges.alpha_x0 * thickness * dy, edges.alpha_x0 * dx / 2, np.full(ny, edges.T_x0)),
            (k[:, -1], edges.alpha_xL * thickness * dy, edges.alpha_xL * dx / 2, np.full(ny, edges.T_xL)),
            (k[0, :], edges.alpha_y * thickness * dx, edges.alpha_y * dy / 2, t_y),
            (k[-1, :], edges.alpha_y * thickness * dx, edges.alpha_y * dy / 2, t_y),
        )
        # the same in index form (corner cells appear twice): alpha B_s s (W/K), alpha d / 2 (W/(m K))
        cells, ga, r, tamb, kind = [], [], [], [], []
        for side, (c, ga_s, r_s, t_s) in enumerate(sides):
            cells.append(c)
            ga.append(np.full(c.size, ga_s))
            r.append(np.full(c.size, r_s))
            tamb.append(t_s)
            kind.append(np.full(c.size, min(side, 2)))  # 0 = x0 (holder up), 1 = xL (holder lo), 2 = gas
        keep = np.concatenate(ga) > 0.0  # insulated edges drop out
        self._e = np.concatenate(cells)[keep]
        self._e_ga = np.concatenate(ga)[keep]
        self._e_r = np.concatenate(r)[keep]
        self._e_tamb = np.concatenate(tamb)[keep]
        self._e_kind = np.concatenate(kind)[keep]
        # sparsity pattern of the Jacobian: diagonal + both face directions
        rows = np.concatenate([np.arange(self.n), a, b])
        cols = np.concatenate([np.arange(self.n), b, a])
        self._pattern = (rows, cols)
        # geometry of the Gershgorin bound: 2 sum of face factors per cell (diagonal + off-diagonal)
        self._row_geometry_max = float((2.0 * (np.bincount(a, g, self.n) + np.bincount(b, g, self.n))).max())
        self._edge_ga_max = float(np.bincount(self._e, self._e_ga, self.n).max()) if keep.any() else 0.0
        self._e_r_max = float(self._e_r.max()) if keep.any() else 0.0
        tamb_all = np.concatenate(tamb)
        self._tamb_range = (float(tamb_all.min()), float(tamb_all.max()))
        lam_tab, t_tab = steel.conductivity_table, steel.temperatures
        self._table_bounds = (
            float(np.max(lam_tab)),
            float(np.min(lam_tab)),
            float(np.max(np.abs(np.diff(lam_tab) / np.diff(t_tab)))),
        )

    @classmethod
    def for_plate(cls, cfg: FurnaceConfig, steel: Steel, edges: EdgeExchange) -> ConductionOperator:
        """Operator on the specimen grid of ``cfg`` (N_x x N_y cells)."""
        s = cfg.specimen
        return cls(s.nx, s.ny, s.length, s.width, s.thickness, steel, edges)

    # ---- evaluation ----
    def edge_conductance(self, T: Array) -> Array:
        """Series conductance (W/K) of each edge face: alpha B_s s / (1 + alpha d / (2 lambda))."""
        lam_e = self.steel.conductivity(T[self._e])
        return self._e_ga / (1.0 + self._e_r / lam_e)

    def heat_flow(self, T: Array, lam: Array | None = None) -> Array:
        """Net conductive heat flow into each cell (W), interior faces plus edges (eqs. 1, 3a-d).

        ``lam`` optionally passes lambda(T) of the cells (W/(m K)) if the caller has it.
        """
        T2 = T.reshape(self.ny, self.nx)
        L2 = (self.steel.conductivity(T) if lam is None else lam).reshape(self.ny, self.nx)
        fx = L2[:, 1:] + L2[:, :-1]
        fx *= T2[:, 1:] - T2[:, :-1]
        fx *= self._gx2
        fy = L2[1:, :] + L2[:-1, :]
        fy *= T2[1:, :] - T2[:-1, :]
        fy *= self._gy2
        Q = np.zeros((self.ny, self.nx))
        Q[:, :-1] += fx
        Q[:, 1:] -= fx
        Q[:-1, :] += fy
        Q[1:, :] -= fy
        q = Q.reshape(-1)
        if self._e.size:  # all edge faces at once (corners twice)
            e = self._e
            lam_e = L2.reshape(-1)[e]
            ge = self._e_r / lam_e
            ge += 1.0
            np.divide(self._e_ga, ge, out=ge)
            ge *= T[e] - self._e_tamb
            q -= np.bincount(e, ge, self.n)
        return q

    def edge_losses(self, T: Array) -> dict[str, float]:
        """Heat lost through the edges (W): 'holder_edges' (3a-b) and 'gas_edges' (3c-d)."""
        loss = self.edge_conductance(T) * (T[self._e] - self._e_tamb)
        return {
            "holder_edges": float(loss[self._e_kind < 2].sum()),
            "gas_edges": float(loss[self._e_kind == 2].sum()),
        }

    def jacobian(self, T: Array) -> sp.csr_matrix:
        """d heat_flow / dT (W/K), sparse, including the lambda'(T) terms."""
        lam = self.steel.conductivity(T)
        dlam = self.steel.conductivity_slope(T)
        a, b, g = self._a, self._b, self._g
        dT = T[b] - T[a]
        lam_f = 0.5 * (lam[a] + lam[b])
        # f = lam_f g dT with lam_f = (lam_a + lam_b) / 2:
        # df/dT_a = g (lam_a' dT / 2 - lam_f), df/dT_b = g (lam_b' dT / 2 + lam_f)
        dfa = g * (0.5 * dlam[a] * dT - lam_f)
        dfb = g * (0.5 * dlam[b] * dT + lam_f)
        # q_a += f, q_b -= f
        diag = np.bincount(a, dfa, self.n) - np.bincount(b, dfb, self.n)
        e = self._e
        Te = T[e]
        den = 1.0 + self._e_r / lam[e]
        ge = self._e_ga / den
        dge = self._e_ga * (self._e_r * dlam[e] / lam[e] ** 2) / den**2
        diag -= np.bincount(e, ge + dge * (Te - self._e_tamb), self.n)
        rows, cols = self._pattern
        vals = np.concatenate([diag, dfb, -dfa])
        return sp.csr_matrix((vals, (rows, cols)), shape=(self.n, self.n))

    def max_row_sum(self, T_min: float, T_max: float) -> float:
        """Upper bound (W/K) of the Gershgorin row sums of :meth:`jacobian` for T_min <= T <= T_max.

        Uses the largest tabulated lambda and the steepest table slope with the largest
        possible temperature difference across a face (T_max - T_min) and between an edge
        cell and its ambient.
        """
        lam_max, lam_min, slope_max = self._table_bounds
        bound = self._row_geometry_max * (lam_max + 0.5 * slope_max * (T_max - T_min))
        dT_edge = max(abs(T_max - self._tamb_range[0]), abs(T_min - self._tamb_range[1]))
        bound += self._edge_ga_max * (1.0 + self._e_r_max * slope_max * dT_edge / lam_min**2)
        return bound
