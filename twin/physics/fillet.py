"""The fillet Omega_f, the region of interest: 0.25-0.75 L_s x 0.2-0.8 W_s (paper section 3.1).

Two quantities are defined over it, here and nowhere else (product.md):

* the **fillet mean**: the area integral of the cell-centred field over Omega_f divided by its
  area, each cell's value counting by the area of the cell inside Omega_f;
  T_mean = sum_k a_k T_k / sum_k a_k.  The plant helpers, the run metrics, the figures and the
  estimator (its c_m = M_theta^T a / sum a, so c_m^T theta is this mean of the model's field on
  the cells) all use :class:`Fillet`, so the true and the estimated mean are the same quantity;
* **T_sup** (section 5.1): max |T - T_ref| over the cells whose centres lie in the closed
  fillet.

Grids are uniform cell-centred grids over the whole specimen (the FD grid, or a stored field's
``x``, ``y``), so each cell spans its centre +- half the spacing.

Example
-------
>>> import numpy as np
>>> from twin.config import load_config
>>> fillet = Fillet.of(load_config())               # the 26 x 17 grid of the default furnace
>>> int(fillet.mask.sum()), round(float(fillet.weights.sum()), 12)
(154, 1.0)
>>> x = np.tile((np.arange(26) + 0.5) / 26, (17, 1))  # T = x / L_s: the exact fillet mean is 0.5
>>> round(float(fillet.mean(x)), 12)
0.5
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.physics.grid import cell_centers

Array = NDArray[np.float64]

#: the fillet in relative coordinates (x / L_s, y / W_s), paper section 3.1
FILLET_X = (0.25, 0.75)
FILLET_Y = (0.2, 0.8)


def fillet_box(L_s: float, W_s: float) -> tuple[float, float, float, float]:
    """The fillet Omega_f as (x0, x1, y0, y1) in m on a specimen of length L_s and width W_s (m).

    >>> fillet_box(4.0, 10.0)
    (1.0, 3.0, 2.0, 8.0)
    """
    return (FILLET_X[0] * L_s, FILLET_X[1] * L_s, FILLET_Y[0] * W_s, FILLET_Y[1] * W_s)


def _overlap(centres: Array, size: float, lo: float, hi: float) -> Array:
    """Length of [c - h/2, c + h/2] inside [lo, hi] for uniform cells of spacing h = size / n."""
    h = size / len(centres)
    return np.clip(np.minimum(centres + h / 2, hi) - np.maximum(centres - h / 2, lo), 0.0, None)


@dataclass(frozen=True, eq=False)
class Fillet:
    """The fillet on one cell-centred grid.

    Attributes
    ----------
    weights : (N_y, N_x) area of each cell inside the fillet over the fillet's area (sum 1)
    mask : (N_y, N_x) cells whose centres lie in the closed fillet (for T_sup)
    """

    weights: Array
    mask: NDArray[np.bool_]

    @classmethod
    def on_grid(cls, x: ArrayLike, y: ArrayLike, L_s: float, W_s: float) -> Fillet:
        """The fillet on the uniform grid with cell centres x (N_x,), y (N_y,) in m."""
        xv, yv = np.asarray(x, float), np.asarray(y, float)
        x0, x1, y0, y1 = fillet_box(L_s, W_s)
        a = np.outer(_overlap(yv, W_s, y0, y1), _overlap(xv, L_s, x0, x1))
        eps_x, eps_y = 1e-12 * L_s, 1e-12 * W_s
        mx = (xv >= x0 - eps_x) & (xv <= x1 + eps_x)
        my = (yv >= y0 - eps_y) & (yv <= y1 + eps_y)
        return cls(weights=a / a.sum(), mask=np.outer(my, mx))

    @classmethod
    def of(cls, cfg: FurnaceConfig) -> Fillet:
        """The fillet on the furnace's FD grid."""
        x, y = cell_centers(cfg)
        return cls.on_grid(x, y, cfg.specimen.length, cfg.specimen.width)

    @property
    def flat_weights(self) -> Array:
        """The weights in the state order k = i + N_x j, (N_s,)."""
        return self.weights.ravel()

    @cached_property
    def flat_indices(self) -> NDArray[np.intp]:
        """State indices of the cells of :attr:`mask` (found once: T_sup asks twice per sample)."""
        return np.flatnonzero(self.mask.ravel())

    def _grid(self, field: ArrayLike) -> Array:
        """A field (..., N_y, N_x) or (..., N_s) as (..., N_y * N_x)."""
        f = np.asarray(field, float)
        n = self.weights.size
        if f.shape[-2:] == self.weights.shape:
            return f.reshape(*f.shape[:-2], n)
        if f.shape[-1:] == (n,):
            return f
        raise ValueError(f"field of shape {f.shape} does not fit a fillet grid of {self.weights.shape}")

    def mean(self, field: ArrayLike) -> Any:
        """Fillet mean (K) of a field (..., N_y, N_x) or (..., N_s) -> (...,)."""
        return self._grid(field) @ self.flat_weights

    def sup(self, field: ArrayLike, T_ref: ArrayLike) -> Any:
        """T_sup = max over the closed fillet's cells |field - T_ref| in K, (...,); T_ref (...,) or scalar."""
        f = self._grid(field)[..., self.flat_indices]
        ref = np.asarray(T_ref, float)
        return np.max(np.abs(f - (ref[..., None] if ref.ndim else ref)), axis=-1)

    def spread(self, field: ArrayLike) -> Any:
        """max over the closed fillet's cells |field - fillet mean| in K (the inhomogeneity about the mean)."""
        return self.sup(field, self.mean(field))
