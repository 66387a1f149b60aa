"""First-order lags of the simulated furnace's sensors and actuators, tau dy/dt = x(t) - y, solved exactly.

Over one sample of length h, with a = exp(-h / tau):

* input held (a thyristor command, zero-order hold): y(h) = u + (y0 - u) a, and the mean of y over
  the sample is u + (y0 - u) (tau / h) (1 - a), so the energy a lamp delivers in the sample is exact;
* input linear from x0 to x1 (the plate temperature under a thermocouple between two samples):

      y(h) = a y0 + (1 - a) x0 + (x1 - x0) (1 - (tau / h) (1 - a)),

  the convolution of the exponential kernel (1/tau) exp(-s / tau) with the ramp.

tau = 0 passes the input through (y = u, resp. y = x1).

Example
-------
>>> import math
>>> y, mean = held_input_step(0.0, 1.0, 0.3, 0.3)           # one time constant after a unit step
>>> round(y, 6) == round(1 - math.exp(-1), 6), round(mean, 4)
(True, 0.3679)
>>> round(float(ramp_input_step(0.0, 0.0, 1.0, 1.0, 1.0)), 6)  # ramp x = t: y(1) = 1 - tau (1 - e^-1)
0.367879
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
X = TypeVar("X", float, Array)


def held_input_step(y0: X, u: X, h: float, tau: float) -> tuple[X, X]:
    """(y at the end of the sample, mean of y over the sample) for the input u held over h (s)."""
    if tau <= 0.0:
        return u, u
    a = math.exp(-h / tau)
    d = y0 - u
    return u + d * a, u + d * (tau / h) * (1.0 - a)


def ramp_input_step(y0: X, x0: X, x1: X, h: float, tau: float) -> X:
    """y at the end of a sample over which the input moves linearly from x0 to x1 (h, tau in s)."""
    if tau <= 0.0:
        return x1
    a = math.exp(-h / tau)
    return a * y0 + (1.0 - a) * x0 + (x1 - x0) * (1.0 - (tau / h) * (1.0 - a))
