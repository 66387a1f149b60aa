"""The specimen's finite-difference grid (paper section 2.1).

N_s = N_x N_y cells of equal size; cell k = i + N_x j, i = 0..N_x-1 along x (length,
x = 0 at the upper holder), j = 0..N_y-1 along y.  Cell centres
x_i = (i + 0.5) L_s / N_x, y_j = (j + 0.5) W_s / N_y.  A field vector T (N_s,) is the image
``T.reshape(N_y, N_x)`` (rows = y, columns = x).

Example
-------
>>> from twin.config import load_config
>>> x, y = cell_centers(load_config())
>>> len(x), len(y), round(float(x[0]), 6)
(26, 17, 0.007692)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig

Array = NDArray[np.float64]


def centers(length: float, n: int) -> Array:
    """Centres (n,) of n equal cells on [0, length] in m: (i + 0.5) length / n."""
    return np.asarray((np.arange(n) + 0.5) * (length / n), dtype=np.float64)


def cell_centers(cfg: FurnaceConfig) -> tuple[Array, Array]:
    """FD cell centres x_i (N_x,), y_j (N_y,) in m."""
    s = cfg.specimen
    return centers(s.length, s.nx), centers(s.width, s.ny)


def cell_coordinates(cfg: FurnaceConfig) -> tuple[Array, Array]:
    """x and y of every cell (N_s,) in the state order k = i + N_x j."""
    x, y = cell_centers(cfg)
    return np.tile(x, len(y)), np.repeat(y, len(x))
