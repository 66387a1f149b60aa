"""The independent furnace's thermocouples and lamps: first-order lags and per-TC biases.

:class:`LaggedThermocouples` follows the plate temperature under each junction, x_i = H T (the
bilinear interpolation of :mod:`twin.furnace.simulated.thermocouples`), with a first-order lag
(``lags.ramp_input_step``: the plate temperature moves linearly between two samples) and reads

    y_i = lagged x_i + beta_i tol(lagged x_i),      beta_i ~ U(-bias, bias), fixed per run,

tol(T) the IEC 60584-1 class 1 tolerance of a type K thermocouple (1.5 K up to 375 C, 0.004 |t|
above; t in C).  The betas come from the run's seed (a stream of their own: the TC noise of a
seed is the same with and without biases).

:class:`LampLag` turns the thyristor commands (group fractions held over a sample) into the mean
radiated power over that sample (``lags.held_input_step``), which the plant holds instead.

Example
-------
>>> import numpy as np
>>> round(float(class1_tolerance(1100.0)), 3)                 # K, at 826.85 C
3.307
>>> lamps = LampLag(3, time_constant=0.3)
>>> mean = lamps.step(np.array([1.0, 0.0, 2.0]), 0.3)     # from off, one time constant; 2.0 saturates at 1
>>> np.round(mean, 4).tolist(), np.round(lamps.power, 4).tolist()
([0.3679, 0.0, 0.3679], [0.6321, 0.0, 0.6321])
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.furnace.simulated.lags import held_input_step, ramp_input_step
from twin.furnace.simulated.thermocouples import Thermocouples
from twin.physics.materials import KELVIN_OFFSET

Array = NDArray[np.float64]

#: IEC 60584-1 class 1, type K: +-1.5 K from -40 C to 375 C, +-0.004 |t| from 375 C to 1000 C
CLASS1_FIXED_K = 1.5
CLASS1_RELATIVE = 0.004
#: entropy of the bias stream, mixed with the run's seed (any constant other than the noise's)
BIAS_STREAM = 60584


def class1_tolerance(T: ArrayLike) -> Array:
    """Tolerance (K) of a class 1 type K thermocouple at T (K)."""
    t_celsius = np.asarray(T, float) - KELVIN_OFFSET
    return np.maximum(CLASS1_FIXED_K, CLASS1_RELATIVE * np.abs(t_celsius))


class LaggedThermocouples:
    """Thermocouples with a first-order lag and a fixed relative bias each (see the module docstring).

    Parameters
    ----------
    tcs : where they sit (their interpolation matrix H)
    T0 : the plate's initial cell temperatures (K); the junctions start in equilibrium with it
    time_constant : s (0: no lag)
    bias : beta_i ~ U(-bias, bias) (0: no bias)
    seed : the run's seed
    """

    def __init__(self, tcs: Thermocouples, T0: ArrayLike, *, time_constant: float, bias: float, seed: int) -> None:
        self.tcs = tcs
        self.time_constant = float(time_constant)
        self._x = tcs.true_values(T0)
        self._y = self._x.copy()
        rng = np.random.default_rng([BIAS_STREAM, int(seed)])
        self.beta = rng.uniform(-bias, bias, self._x.shape) if bias > 0 else np.zeros_like(self._x)

    def advance(self, T: ArrayLike, h: float) -> None:
        """The plate reached the cell temperatures T (K) after h s; the junctions follow."""
        x1 = self.tcs.true_values(T)
        self._y = ramp_input_step(self._y, self._x, x1, h, self.time_constant)
        self._x = x1

    @property
    def junction(self) -> Array:
        """The junctions' temperatures (K), before the bias."""
        return self._y.copy()

    def values(self) -> Array:
        """Readings without noise (K): lagged temperature plus bias."""
        return self._y + self.beta * class1_tolerance(self._y)


class LampLag:
    """Radiated power (fractions of u_max per group) lagging the commands, starting with the lamps off."""

    def __init__(self, n: int, *, time_constant: float) -> None:
        self.time_constant = float(time_constant)
        self.power = np.zeros(n)

    def step(self, command: ArrayLike, h: float) -> Array:
        """Hold ``command`` (clipped to [0, 1], as the thyristors saturate) over h s; the mean power over it."""
        u = np.clip(np.asarray(command, float), 0.0, 1.0)
        self.power, mean = held_input_step(self.power, u, h, self.time_constant)
        return np.asarray(mean)
