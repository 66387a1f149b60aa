"""Newton-cooling heat losses of the specimen: inert gas and holders (paper eqs. 3 and 6).

Shared by the full-order plant (FD cells) and the reduced FE model, so both see the
same losses.  Everything here is *linear* in the temperature:

* face losses per FD cell k (W/m^2 of plate area, both faces summed), eq. (6)::

      q_c + q_h = d * T - b,
      q_c = 2 alpha_ig (1 - f_k) (T_k - T_ig(x_k))      (gas on the exposed part, both faces)
      q_h = 2 alpha_h  f_k       (T_k - T_h(x_k))       (holder jaws on the clamped part, both faces)

  with f_k the clamped fraction of cell k (jaws of length ``holders.clamp_length`` at each
  end) and T_h = T_h^up for x < L_s / 2, T_h^lo else;
* edge losses (3a-d) per unit edge-face area: alpha (T - T_env) with
  T_env = T_h^up at x = 0, T_h^lo at x = L_s (coefficient alpha_h) and T_ig(x) at y = 0, W_s
  (coefficient alpha_ig).

The inert-gas profile T_ig(x) is linear from ``inert_gas.temperature_top`` at x = 0 to
``inert_gas.temperature_bottom`` at x = L_s (quasi-stationary, section 2.1).

Example
-------
>>> from twin.config import load_config
>>> cfg = load_config()
>>> d, b = face_loss_coefficients(cfg)
>>> d.shape
(442,)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.physics.grid import cell_centers

Array = NDArray[np.float64]


def inert_gas_temperature(cfg: FurnaceConfig, x: ArrayLike) -> Array:
    """Quasi-stationary inert-gas temperature T_ig(x) in K (linear in x, eq. 3c-d, 6).

    Parameters
    ----------
    cfg : furnace configuration
    x : positions along the specimen length in m (0 = top, L_s = bottom)
    """
    g, L = cfg.inert_gas, cfg.specimen.length
    xr = np.asarray(x, float) / L
    return g.temperature_top + (g.temperature_bottom - g.temperature_top) * xr


def clamped_fraction(cfg: FurnaceConfig) -> Array:
    """Fraction (0..1) of each FD cell's area under the holder jaws, shape (N_s,).

    The jaws cover 0 <= x <= l_c and L_s - l_c <= x <= L_s over the full width, with
    l_c = ``holders.clamp_length``.  Order k = i + N_x j.
    """
    s, lc = cfg.specimen, cfg.holders.clamp_length
    dx = s.length / s.nx
    x0 = np.arange(s.nx) * dx
    x1 = x0 + dx
    upper = np.clip(np.minimum(x1, lc) - x0, 0.0, dx)
    lower = np.clip(x1 - np.maximum(x0, s.length - lc), 0.0, dx)
    frac_x = (upper + lower) / dx
    return np.tile(frac_x, s.ny)


def holder_temperature(cfg: FurnaceConfig, x: ArrayLike) -> Array:
    """Holder temperature seen at x in K: T_h^up on the upper half, T_h^lo on the lower half."""
    h = cfg.holders
    upper = np.asarray(x, float) < 0.5 * cfg.specimen.length
    return np.where(upper, h.temperature_upper, h.temperature_lower)


def face_loss_coefficients(cfg: FurnaceConfig, alpha_scale: float = 1.0) -> tuple[Array, Array]:
    """Coefficients of the face losses q_c + q_h = d * T - b per FD cell (eq. 6).

    Parameters
    ----------
    cfg : furnace configuration
    alpha_scale : factor on both alpha_ig and alpha_h (plant mismatch ``1 + Mismatch.alpha``)

    Returns
    -------
    d : (N_s,) W/(m^2 K), both faces summed
    b : (N_s,) W/m^2
    """
    s = cfg.specimen
    xc, _ = cell_centers(cfg)
    x = np.tile(xc, s.ny)
    f = clamped_fraction(cfg)
    a_ig = 2.0 * alpha_scale * cfg.inert_gas.alpha * (1.0 - f)
    a_h = 2.0 * alpha_scale * cfg.holders.alpha * f
    d = a_ig + a_h
    b = a_ig * inert_gas_temperature(cfg, x) + a_h * holder_temperature(cfg, x)
    return d, b


@dataclass(frozen=True)
class EdgeLosses:
    """Coefficients of the edge conditions (3a-d): flux out = alpha (T - T_env) in W/m^2.

    ``alpha_x`` / ``T_top`` / ``T_bottom`` belong to the edges x = 0 and x = L_s,
    ``alpha_y`` to y = 0 and y = W_s, where T_env = T_ig(x).
    """

    alpha_x: float
    T_top: float
    T_bottom: float
    alpha_y: float


def edge_losses(cfg: FurnaceConfig, alpha_scale: float = 1.0) -> EdgeLosses:
    """Edge heat-transfer data of the boundary conditions (3a-d)."""
    h = cfg.holders
    return EdgeLosses(
        alpha_x=alpha_scale * h.alpha,
        T_top=h.temperature_upper,
        T_bottom=h.temperature_lower,
        alpha_y=alpha_scale * cfg.inert_gas.alpha,
    )
