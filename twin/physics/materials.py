"""Temperature-dependent steel properties c_p(T) and lambda(T) (paper eq. 1).

Piecewise-linear interpolation of the table in the furnace config (furnace.md),
held constant outside the table.  The derivatives are the slopes of the same
interpolant, so analytic Jacobians stay consistent with the values.

Example
-------
>>> from twin.config import load_config
>>> steel = Steel.from_config(load_config())
>>> round(float(steel.heat_capacity(1042.0)), 1)
1500.0
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig

Array = NDArray[np.float64]

#: K at 0 C (tolerances and furnace readings stated in C)
KELVIN_OFFSET = 273.15


@dataclass(frozen=True)
class Steel:
    """Tabulated c_p(T) in J/(kg K) and lambda(T) in W/(m K); density in kg/m^3."""

    temperatures: Array
    cp_table: Array
    conductivity_table: Array
    density: float

    @classmethod
    def from_config(cls, cfg: FurnaceConfig) -> Steel:
        m = cfg.material
        return cls(
            np.asarray(m.temperatures, float),
            np.asarray(m.heat_capacity, float),
            np.asarray(m.conductivity, float),
            cfg.specimen.density,
        )

    def heat_capacity(self, T: ArrayLike) -> Array:
        """c_p(T) in J/(kg K)."""
        return np.interp(np.asarray(T, float), self.temperatures, self.cp_table)

    def conductivity(self, T: ArrayLike) -> Array:
        """lambda(T) in W/(m K)."""
        return np.interp(np.asarray(T, float), self.temperatures, self.conductivity_table)

    @cached_property
    def _cp_slopes(self) -> Array:
        """d c_p / dT on each table interval (made once: a plan asks for the slope thousands of times)."""
        return np.diff(self.cp_table) / np.diff(self.temperatures)

    @cached_property
    def _conductivity_slopes(self) -> Array:
        """d lambda / dT on each table interval."""
        return np.diff(self.conductivity_table) / np.diff(self.temperatures)

    def _slope(self, T: ArrayLike, slopes: Array) -> Array:
        t = np.asarray(T, float)
        seg = np.clip(np.searchsorted(self.temperatures, t, side="right") - 1, 0, len(slopes) - 1)
        out = slopes[seg]
        return np.where((t < self.temperatures[0]) | (t > self.temperatures[-1]), 0.0, out)

    def heat_capacity_slope(self, T: ArrayLike) -> Array:
        """d c_p / dT in J/(kg K^2)."""
        return self._slope(T, self._cp_slopes)

    def conductivity_slope(self, T: ArrayLike) -> Array:
        """d lambda / dT in W/(m K^2)."""
        return self._slope(T, self._conductivity_slopes)

    def enthalpy(self, T: ArrayLike) -> Array:
        """Specific enthalpy h(T) = int_{T_0}^{T} c_p dT' in J/kg, T_0 = first table point.

        Exact integral of the piecewise-linear c_p (trapezoids), used for energy balances.
        """
        t = np.atleast_1d(np.asarray(T, float))
        grid = self.temperatures
        cum = np.concatenate([[0.0], np.cumsum(np.diff(grid) * (self.cp_table[1:] + self.cp_table[:-1]) / 2)])
        tc = np.clip(t, grid[0], grid[-1])
        seg = np.clip(np.searchsorted(grid, tc, side="right") - 1, 0, len(grid) - 2)
        cp_at = self.heat_capacity(tc)
        h = cum[seg] + (tc - grid[seg]) * (self.cp_table[seg] + cp_at) / 2
        # constant c_p beyond the table
        h = h + np.where(t < grid[0], (t - grid[0]) * self.cp_table[0], 0.0)
        h = h + np.where(t > grid[-1], (t - grid[-1]) * self.cp_table[-1], 0.0)
        return h.reshape(np.shape(T)) if np.ndim(T) else h[0]

    def mean_heat_capacity(self, t_low: float, t_high: float) -> float:
        """Enthalpy-equivalent constant c_p over [t_low, t_high] in J/(kg K)."""
        return float((self.enthalpy(t_high) - self.enthalpy(t_low)) / (t_high - t_low))
