"""The estimated field's standard deviation per grid cell, from the filter's covariance P (issue 25).

The estimate at a point xi is T_hat(xi) = phi(xi)^T theta (eq. 7), so with theta's error covariance P

    sigma(xi)^2 = phi(xi)^T P phi(xi) + r^2,

where r (K) is the part of the true field no combination of the hat functions can represent
(the FE grid's representation error, ``[ekf.model_error] representation_rms``; 0 = P alone).  On the FD
cell centres phi(xi_c) is row c of M_theta: a bilinear hat row with at most 2 x 2 non-zero weights, so
sigma_c^2 takes 16 entries of P (about 7000 products for 442 cells, not the 442 x 105 x 105 of
diag(M_theta P M_theta^T)).  The fillet mean's standard deviation is sqrt(c_m^T P c_m + r_m^2) with the
fillet-mean weights c_m of :class:`twin.model.fe.FEModel` (eq. 19 on the cells); r_m = r, taking the
representation error as one common offset over the fillet (the conservative reading).

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> from twin.model.fe import FEModel
>>> fe = FEModel(small_config())
>>> u = FieldUncertainty(fe)
>>> s = u.field_sigma(4.0 * np.eye(fe.n))   # independent nodes with sigma 2 K: 2 sqrt(sum w^2), sum w = 1
>>> s.shape, round(float(s.max()), 6), bool(s.min() >= 2.0 * np.sqrt(4 * 0.25**2) - 1e-9)
((17, 26), 2.0, True)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def _nonzero_hats(hats: Array) -> tuple[NDArray[np.intp], Array]:
    """The (at most 2) non-zero hat functions of each row of a 1D hat matrix: indices and weights, (rows, 2)."""
    rows = hats.shape[0]
    idx = np.zeros((rows, 2), np.intp)
    w = np.zeros((rows, 2))
    for r in range(rows):
        nz = np.flatnonzero(hats[r])
        if len(nz) > 2:
            raise ValueError("a 1D hat row has more than two non-zero functions")
        idx[r, : len(nz)], w[r, : len(nz)] = nz, hats[r, nz]
    return idx, w


class FieldUncertainty:
    """sigma per FD cell and of the fillet mean from a covariance P of the FE nodes (module docstring).

    Parameters
    ----------
    fe : the reduced FE model (:class:`twin.model.fe.FEModel`): node lines, cell hats, ``c_m``
    representation_rms : r in K, added in quadrature (the FE grid's representation error)
    """

    def __init__(self, fe: Any, representation_rms: float = 0.0) -> None:
        hy, hxT = fe._cell_hats  # (N_y, n_y nodes), (n_x nodes, N_x): M_theta = kron(H_y, H_x^T)
        iy, wy = _nonzero_hats(np.asarray(hy, float))
        ix, wx = _nonzero_hats(np.asarray(hxT, float).T)
        n_x = fe.nx_nodes
        self.shape = (hy.shape[0], hxT.shape[1])
        # cell c = (a, b) -> its 4 nodes k = i + n_x j and weights g_j(y_a) h_i(x_b), cells in image order
        k = iy[:, None, :, None] * n_x + ix[None, :, None, :]  # (N_y, N_x, 2, 2)
        w = wy[:, None, :, None] * wx[None, :, None, :]
        self._idx = k.reshape(-1, 4)
        self._w = w.reshape(-1, 4)
        self._rows = self._idx[:, :, None]
        self._cols = self._idx[:, None, :]
        self._ww = (self._w[:, :, None] * self._w[:, None, :]).reshape(-1, 16)  # w_i w_j per cell
        self._flat: dict[int, NDArray[np.intp]] = {}  # per leading dimension of P: flat indices of the 4 x 4 blocks
        self.c_m = np.asarray(fe.c_m, float)
        self.representation_var = float(representation_rms) ** 2

    def cell_variance(self, P: NDArray[np.floating[Any]]) -> Array:
        """phi_c^T P phi_c + r^2 for every cell, (N_y, N_x) in K^2 (P: (n, n) or larger, nodes first)."""
        m = P.shape[1]
        flat = self._flat.get(m)
        if flat is None:
            flat = self._flat[m] = (self._rows * m + self._cols).reshape(-1, 16)
        block = np.take(P, flat)  # (cells, 16) entries of P, in its own memory order (C contiguous)
        var = np.einsum("ck,ck->c", self._ww, block) + self.representation_var
        return np.clip(var, 0.0, None).reshape(self.shape)

    def field_sigma(self, P: NDArray[np.floating[Any]]) -> Array:
        """The estimated field's standard deviation at the cell centres, (N_y, N_x) in K (the shape of
        ``field_hat``)."""
        return np.asarray(np.sqrt(self.cell_variance(P)))

    def mean_sigma(self, P: NDArray[np.floating[Any]]) -> float:
        """Standard deviation of the fillet-mean estimate c_m^T theta in K."""
        n = len(self.c_m)
        Pn = np.asarray(P[:n, :n], float)
        return float(np.sqrt(max(float(self.c_m @ Pn @ self.c_m), 0.0) + self.representation_var))
