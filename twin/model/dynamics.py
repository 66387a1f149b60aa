"""The interface of the discrete-time reduced model (eq. 12a) that estimator and controller use.

:class:`twin.model.discrete.DiscreteModel` implements it; the EKF, the OCP and the LQG design
depend only on this protocol, so their tests can drive them with small stand-in systems.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


class DiscreteDynamics(Protocol):
    """theta_{j+1} = F(theta_j, u_j) with its Jacobians (eqs. 12a, 16, 23) and the fillet weights."""

    @property
    def n(self) -> int: ...

    @property
    def m(self) -> int: ...

    @property
    def t_s(self) -> float: ...

    @property
    def c_m(self) -> Array: ...

    @property
    def W(self) -> Array: ...

    def step(self, theta: Array, u: Array) -> Array: ...

    def jac_theta(self, theta: Array, u: Array) -> Array: ...

    def jac_u(self, theta: Array, u: Array) -> Array: ...
