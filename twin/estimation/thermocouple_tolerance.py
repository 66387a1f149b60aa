"""What the thermocouples' datasheet says about their systematic error, as the twin knows it (issue 25).

A thermocouple's reading is off by a deviation that is fixed for that thermocouple (its wire's Seebeck
coefficient), bounded by its tolerance class: for type K, class 1 of IEC 60584-1, +-1.5 K up to 375 C and
+-0.004 |t| above (t in C).  The filter cannot see this deviation (three TCs, three unknown offsets and an
unknown field), so the twin carries it as *consider* states of the reported covariance
(:mod:`twin.estimation.process_noise`): beta_i with y_i = C_i theta + beta_i tol(y_i) + v_i, beta_i uniform in
[-1, 1] (the GUM's type-B reading of a stated tolerance, JCGM 100 4.3.7: variance 1/3).

The numbers are the datasheet's, from ``[ekf.model_error] tc_tolerance_fixed`` and ``tc_tolerance_relative``
of the furnace file, not the simulated furnace's bias generator.

Example
-------
>>> import numpy as np
>>> np.round(tolerance(np.array([300.0, 1100.0]), 1.5, 0.004), 3).tolist()   # 0.004 x 826.85 C
[1.5, 3.307]
>>> round(BETA_VARIANCE, 4)
0.3333
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.physics.materials import KELVIN_OFFSET

Array = NDArray[np.float64]

#: variance of a deviation uniform over +-1 tolerance (JCGM 100, 4.3.7: a^2 / 3 with a = 1)
BETA_VARIANCE = 1.0 / 3.0


def tolerance(T: ArrayLike, fixed: float, relative: float) -> Array:
    """max(fixed, relative |t|) in K at T (K), t = T - 273.15 C; NaN where T is NaN."""
    t_celsius = np.asarray(T, float) - KELVIN_OFFSET
    return np.asarray(np.fmax(fixed, relative * np.abs(t_celsius)) + 0.0 * t_celsius)
