"""Two numerical building blocks shared by the plant, the reduced model and the controller.

* :func:`damped_newton`: Newton's method with a step cap, for the steady states of the
  plant (eqs. 1-6 with dT/dt = 0) and of the reduced model (eq. 12a with theta = F(theta, u)),
  where the T^4 radiation terms make far Newton steps overshoot;
* :func:`heun_step`: one step of Heun's method (explicit trapezoidal rule), used to start the
  plant's Adams-Bashforth integrator and by the feedforward's coarse shooting.

Example
-------
>>> import numpy as np
>>> x = damped_newton(lambda x: x**2 - 2.0, lambda x: np.diag(2.0 * x), np.array([1.0]), tol=1e-12)
>>> round(float(x[0]), 12)
1.414213562373
>>> float(heun_step(lambda t, x: -x, 0.0, np.array([1.0]), 0.1)[0])   # 1 - h + h^2 / 2
0.905
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

log = logging.getLogger(__name__)

Array = NDArray[np.float64]


class NewtonError(ArithmeticError):
    """Newton's method did not converge."""


def damped_newton(
    residual: Callable[[Array], Array],
    jacobian: Callable[[Array], Array],
    x0: Array,
    *,
    tol: float,
    max_iter: int = 60,
    max_step: float = math.inf,
    floor: float = -math.inf,
    what: str = "Newton",
    error: type[Exception] = NewtonError,
) -> Array:
    """Solve r(x) = 0 by x <- max(x + s dx, floor), J(x) dx = -r(x), s = min(1, max_step / max|dx|).

    Parameters
    ----------
    residual, jacobian : r(x) (n,) and dr/dx (n, n)
    x0 : start (n,)
    tol : stop when an undamped step max|dx| is below ``tol`` (units of x)
    max_iter : iterations before ``error`` is raised
    max_step : cap on max|s dx| per iteration (units of x)
    floor : lower bound of every component of x (e.g. 1 K: temperatures stay positive)
    what, error : the message and the exception type on failure
    """
    x = np.array(x0, dtype=float)
    for it in range(max_iter):
        dx = sla.solve(jacobian(x), -residual(x))
        big = float(np.max(np.abs(dx))) if dx.size else 0.0
        s = min(1.0, max_step / max(big, 1e-300))
        x = np.maximum(x + s * dx, floor)
        if s == 1.0 and big < tol:
            log.debug("%s: converged in %d iterations", what, it + 1)
            return x
    raise error(f"{what} did not converge in {max_iter} iterations")


def heun_step(f: Callable[[float, Array], Array], t: float, x: Array, h: float, f0: Array | None = None) -> Array:
    """x(t + h) by Heun's method: x + h/2 (k1 + k2), k1 = f(t, x), k2 = f(t + h, x + h k1).

    ``f0`` = f(t, x) if the caller has it already (saves one evaluation).
    """
    k1 = f(t, x) if f0 is None else f0
    k2 = f(t + h, x + h * k1)
    return x + (0.5 * h) * (k1 + k2)
