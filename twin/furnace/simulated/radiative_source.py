"""The plant's radiative source term q_r of eq. (4), on its own exchange-factor tables.

    q_r = P1(eta) [T^4; T_w^4] + P2(eta) u_lamp                                  (4)

in W/m^2 of plate area (both faces, positive = the plate loses heat), with P(eta) the linear
interpolation (hat functions, :mod:`twin.physics.motion`) between the tabulated positions.
The tables are rearranged once for the time stepping: the wall term T_w^4 is folded into a
constant column, the lamp columns are scaled to group (or lamp) fractions of u_max, and
between table nodes k and k + 1 both blocks are adjacent in memory, so one (2 N_s x N_s)
mat-vec serves both and P(eta) is never built.

Example
-------
>>> import numpy as np
>>> from types import SimpleNamespace
>>> from twin.config import small_config
>>> cfg = small_config()
>>> n = cfg.specimen.n_states
>>> rad = SimpleNamespace(P1=np.zeros((1, n, n + 1)), P2=np.ones((1, n, cfg.lamps.n_lamps)), eta_nodes=[0.0],
...                       wall_temperatures=np.array([300.0]), lamp_flux_max=np.full(cfg.lamps.n_lamps, -2.0))
>>> src = PlantRadiation(cfg, rad)
>>> v1 = np.array([0.5, 0, 0, 0, 0, 0, 1.0])    # group T1h at half power, then the wall column
>>> float(src.flux(np.full(n, 1000.0), v1, False, 0.0)[0])   # 2 lamps x 0.5 x -2 W/m^2
-2.0
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.physics.motion import hat_interval

Array = NDArray[np.float64]


class PlantRadiation:
    """Eq. (4) on the tables of a radiation model (:class:`twin.radiation.RadiationModel`-like).

    Parameters
    ----------
    cfg : the furnace (lamp groups)
    radiation : ``P1`` (n_eta, N_s, N_s + N_w), ``P2`` (n_eta, N_s, N_lamps), ``eta_nodes``,
        ``wall_temperatures``, ``lamp_flux_max`` (W/m^2 per lamp at u = 1)
    lamp_scale : factor on every lamp's flux (1 + lamp-efficiency deviation)
    dtype : precision of the P1 specimen block in :meth:`flux` (float32 by default: the mat-vec is
        memory bound and float32 halves the traffic; its rounding, ~0.01 W/m^2 against
        ~500 W/(m^2 K), is far below the Monte-Carlo noise of P1).  :meth:`matrices` is float64.
    """

    def __init__(self, cfg: FurnaceConfig, radiation: Any, *, lamp_scale: float = 1.0,
                 dtype: type = np.float32) -> None:
        n = cfg.specimen.n_states
        P1 = np.asarray(radiation.P1, float)
        if P1.shape[1] != n or P1.shape[2] < n:
            raise ValueError(f"radiation model P1 has shape {P1.shape}, plant has {n} cells")
        self.n = n
        self.eta_nodes = np.asarray(radiation.eta_nodes, float)
        self._eta_list = [float(v) for v in self.eta_nodes]
        self.P1s = np.ascontiguousarray(P1[:, :, :n])  # (n_eta, N, N)  W/(m^2 K^4)
        self._P1s_step: NDArray[Any] = self.P1s.astype(dtype)
        self._dtype = dtype
        Tw4 = np.asarray(radiation.wall_temperatures, float) ** 4
        self.q_wall = P1[:, :, n:] @ Tw4  # (n_eta, N) W/m^2, walls at known temperature
        flux_max = np.asarray(radiation.lamp_flux_max, float) * lamp_scale
        self.P2_lamps = np.ascontiguousarray(np.asarray(radiation.P2, float) * flux_max)  # per lamp fraction
        self.P2_groups = np.ascontiguousarray(self.P2_lamps @ cfg.group_matrix)  # per group fraction
        # [P2 | q_wall] so that one mat-vec with [v; 1] gives lamps + walls
        self._S_groups = np.ascontiguousarray(np.concatenate([self.P2_groups, self.q_wall[:, :, None]], axis=2))
        self._S_lamps = np.ascontiguousarray(np.concatenate([self.P2_lamps, self.q_wall[:, :, None]], axis=2))
        #: max over positions and rows of sum_j |P1_kj| (for the Gershgorin bound), W/(m^2 K^4)
        self.row_sum_max = float(np.abs(self.P1s).sum(axis=2).max())

    def _blend(self, M: NDArray[Any], x: NDArray[Any], eta: float) -> Array:
        """(1 - w) M_k x + w M_{k+1} x with one mat-vec over both adjacent blocks."""
        k, w = hat_interval(self._eta_list, eta)
        if w == 0.0:
            return np.asarray(M[k] @ x)
        r = M[k : k + 2].reshape(2 * self.n, -1) @ x
        q = r[: self.n]
        q *= 1.0 - w
        q += w * r[self.n :]
        return np.asarray(q)

    def flux(self, T: Array, v1: Array, per_lamp: bool, eta: float) -> Array:
        """q_r (N_s,) W/m^2 of eq. (4); ``v1`` = [input fractions; 1] (``Plant.inputs``)."""
        T4 = T * T
        T4 *= T4
        q = self._blend(self._S_lamps if per_lamp else self._S_groups, v1, eta)
        q += self._blend(self._P1s_step, T4.astype(self._dtype), eta)
        return q

    def lamp_flux(self, v: Array, per_lamp: bool, eta: float) -> Array:
        """The lamps' part P2(eta) u_lamp (N_s,) W/m^2 (negative: absorbed) for fractions v."""
        return self._blend(self.P2_lamps if per_lamp else self.P2_groups, v, eta)

    def matrices(self, weights: ArrayLike) -> tuple[Array, Array, Array]:
        """Weighted P1 specimen block (N, N), wall flux (N,), P2 per group fraction (N, 6), float64.

        ``weights`` are hat weights or period-averaged weights (eq. 11b).
        """
        w = np.asarray(weights, float)
        return np.tensordot(w, self.P1s, axes=1), w @ self.q_wall, np.tensordot(w, self.P2_groups, axes=1)
