"""Thermocouples: the plant's field read at given positions (paper section 3.2).

A thermocouple at xi = (x, y) reads the bilinear interpolation of the cell-centred field
T(x_i, y_j), x_i = (i + 0.5) L_s / N_x, y_j = (j + 0.5) W_s / N_y, plus Gaussian noise.
Between the outermost cell centres and the plate edge the field is held constant (the
nearest centre line), so any point of the plate can be read.

Example
-------
>>> import numpy as np
>>> from twin.config import load_config
>>> cfg = load_config()
>>> tcs = Thermocouples(cfg, cfg.tc_positions())
>>> tcs.read(np.full(442, 1000.0), np.random.default_rng(0), noise=0.0)
array([1000., 1000., 1000., 1000.])
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig

Array = NDArray[np.float64]


def _axis_weights(p: float, n: int, size: float) -> tuple[int, int, float]:
    """Neighbouring centre indices (i0, i1) and weight of i1 for the coordinate p on one axis."""
    s = p / size * n - 0.5  # fractional cell-centre index
    s = min(max(s, 0.0), n - 1.0)
    i0 = min(int(np.floor(s)), n - 2)
    return i0, i0 + 1, s - i0


def interpolation_matrix(cfg: FurnaceConfig, positions: Sequence[tuple[float, float]]) -> Array:
    """H (n, N_s) with H @ T = bilinear interpolation of the cell-centred field at the positions (m)."""
    s = cfg.specimen
    H = np.zeros((len(positions), s.nx * s.ny))
    for r, (x, y) in enumerate(positions):
        if not (0.0 <= x <= s.length and 0.0 <= y <= s.width):
            raise ValueError(f"position ({x}, {y}) m lies outside the specimen {s.length} x {s.width} m")
        i0, i1, wx = _axis_weights(x, s.nx, s.length)
        j0, j1, wy = _axis_weights(y, s.ny, s.width)
        for i, fx in ((i0, 1.0 - wx), (i1, wx)):
            for j, fy in ((j0, 1.0 - wy), (j1, wy)):
                H[r, i + s.nx * j] += fx * fy
    return H


class Thermocouples:
    """Thermocouples at absolute positions (m) on the specimen.

    Parameters
    ----------
    cfg : FurnaceConfig
    positions_abs : sequence of (x, y) in m, e.g. ``cfg.tc_positions()``
    """

    def __init__(self, cfg: FurnaceConfig, positions_abs: Sequence[tuple[float, float]]) -> None:
        self.positions = np.asarray(positions_abs, float).reshape(-1, 2)
        self.H = interpolation_matrix(cfg, [tuple(p) for p in self.positions])

    def true_values(self, T: ArrayLike) -> Array:
        """Noise-free readings (n,) in K."""
        return self.H @ np.asarray(T, float)

    def read(self, T: ArrayLike, rng: np.random.Generator, noise: float) -> Array:
        """Readings (n,) in K: interpolated field plus N(0, noise^2) noise (noise in K)."""
        y = self.true_values(T)
        if noise > 0.0:
            y = y + noise * rng.standard_normal(y.shape)
        return y
