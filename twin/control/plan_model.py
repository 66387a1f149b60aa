"""The model the controller plans with: the discrete model (12a) with c_p(T), and inputs scaled for a reserve.

The paper's reduced model has a constant, enthalpy-equivalent heat capacity c_bar (eq. 9 with the mean of
c_p over ``fe.capacity_range``).  Steel's c_p rises from ~480 J/(kg K) at 300 K to its Curie peak near
1000 K, so a plan made with c_bar heats the cold plate too slowly and the hot plate too fast: the plan
itself is biased, and the feedback has to make up for it while the reference moves.
:class:`CapacityModel` makes the plan (and the LQG / MPC linearisation along it) with the table's c_p(T),
lumped at the nodes like the estimator's ``fe.heat_capacity = "temperature"``
(:meth:`twin.model.parametric.ParametricModel.capacity_scaling`)::

    f_cp(theta, u) = D(theta) f(theta, u),   D_i = c_bar / c_p(theta_i)
    dF_cp/dtheta  = I + D (dF/dtheta - I) + t_s diag(f dD/dtheta)
    dF_cp/du      = D dF/du

D changes the rates, not the steady states (f_cp = 0 where f = 0).

:class:`ScaledInputs` is the same model seen through u = s u': the feedforward OCP plans u' in [0, 1]
and applies s u', so the plan never uses more than the fraction s of u_max (``[control]
feedforward_limit``) and leaves the rest to the feedback.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> from twin.model.discrete import discrete_model
>>> from twin.radiation import radiation_model
>>> cfg = small_config()
>>> base = discrete_model(cfg, radiation_model(cfg))
>>> model = CapacityModel.of(base, cfg)
>>> th = np.full(base.n, 300.0)   # cold: c_p(300 K) < c_bar, the plate heats faster than the paper's model says
>>> u = np.full(6, 0.5)
>>> bool(np.all(model.rhs(th, u) > base.rhs(th, u)))
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.physics.materials import Steel

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class CapacityModel:
    """A :class:`twin.model.discrete.DiscreteModel` with the heat capacity c_p(theta) (module docstring).

    ``base`` keeps its meaning for everything that does not depend on the rates (fe, c_m, W, steady states).
    """

    base: Any  # twin.model.discrete.DiscreteModel
    steel: Steel
    c_bar: float

    @classmethod
    def of(cls, base: Any, cfg: FurnaceConfig) -> CapacityModel:
        return cls(base, Steel.from_config(cfg), float(base.fe.heat_capacity))

    # -- what does not change
    @property
    def n(self) -> int:
        return int(self.base.n)

    @property
    def m(self) -> int:
        return int(self.base.m)

    @property
    def t_s(self) -> float:
        return float(self.base.t_s)

    @property
    def c_m(self) -> Array:
        return np.asarray(self.base.c_m, float)

    @property
    def W(self) -> Array:
        return np.asarray(self.base.W, float)

    @property
    def fe(self) -> Any:
        return self.base.fe

    @property
    def M_theta(self) -> Array:
        return np.asarray(self.base.M_theta, float)

    @property
    def B(self) -> Array:
        return np.asarray(self.base.B, float)

    @property
    def oscillation(self) -> Any:
        return self.base.oscillation

    def steady_state(self, u: ArrayLike, theta0: ArrayLike | None = None) -> Array:
        """Steady states do not depend on the capacity."""
        return np.asarray(self.base.steady_state(u, theta0), float)

    def hold_powers(self, T_mean: float, distribution: ArrayLike | None = None) -> Array:
        return np.asarray(self.base.hold_powers(T_mean, distribution), float)

    # -- the rates
    def scaling(self, theta: ArrayLike) -> tuple[Array, Array]:
        """D_i = c_bar / c_p(theta_i) and dD_i / dtheta_i (1/K)."""
        th = np.asarray(theta, float)
        cp = self.steel.heat_capacity(th)
        return self.c_bar / cp, -self.c_bar * self.steel.heat_capacity_slope(th) / cp**2

    def capacity_ratio(self, theta: ArrayLike) -> Array:
        """D_i = c_bar / c_p(theta_i) alone (the rates need no slope: a plan's sweeps call this thousands of times)."""
        return self.c_bar / self.steel.heat_capacity(np.asarray(theta, float))

    def rhs(self, theta: ArrayLike, u: ArrayLike) -> Array:
        """f_cp = D(theta) f(theta, u) in K/s."""
        return np.asarray(self.capacity_ratio(theta) * self.base.rhs(theta, u), float)

    def step(self, theta: ArrayLike, u: ArrayLike) -> Array:
        th = np.asarray(theta, float)
        return th + self.t_s * self.rhs(th, u)

    def jac_theta(self, theta: ArrayLike, u: ArrayLike | None = None) -> Array:
        """I + D (dF/dtheta - I) + t_s diag(f dD/dtheta) (product rule on D f)."""
        th = np.asarray(theta, float)
        uu = np.zeros(self.m) if u is None else np.asarray(u, float)
        D, dD = self.scaling(th)
        J = D[:, None] * np.asarray(self.base.jac_theta(th, uu), float)
        J[np.diag_indices(self.n)] += (1.0 - D) + self.t_s * np.asarray(self.base.rhs(th, uu), float) * dD
        return J

    def jac_u(self, theta: ArrayLike | None = None, u: ArrayLike | None = None) -> Array:
        """D(theta) t_s B (n, m); needs theta (the capacity depends on it)."""
        if theta is None:
            raise ValueError("CapacityModel.jac_u needs the state: c_p depends on it")
        D = self.capacity_ratio(theta)
        return np.asarray(D[:, None] * self.base.jac_u(theta, u), float)


@dataclass(frozen=True, eq=False)
class ScaledInputs:
    """A model seen through u = scale u' (0 < scale <= 1): F'(theta, u') = F(theta, scale u')."""

    model: Any
    scale: float

    @property
    def n(self) -> int:
        return int(self.model.n)

    @property
    def m(self) -> int:
        return int(self.model.m)

    @property
    def t_s(self) -> float:
        return float(self.model.t_s)

    @property
    def c_m(self) -> Array:
        return np.asarray(self.model.c_m, float)

    @property
    def W(self) -> Array:
        return np.asarray(self.model.W, float)

    def step(self, theta: ArrayLike, u: ArrayLike) -> Array:
        return np.asarray(self.model.step(theta, self.scale * np.asarray(u, float)), float)

    def jac_theta(self, theta: ArrayLike, u: ArrayLike) -> Array:
        return np.asarray(self.model.jac_theta(theta, self.scale * np.asarray(u, float)), float)

    def jac_u(self, theta: ArrayLike, u: ArrayLike) -> Array:
        return self.scale * np.asarray(self.model.jac_u(theta, self.scale * np.asarray(u, float)), float)


def plan_model(model: Any, cfg: FurnaceConfig) -> Any:
    """The model the controller plans with: ``model`` with c_p(T) if ``[control] plan_heat_capacity`` says so."""
    if cfg.control.plan_heat_capacity == "temperature":
        return CapacityModel.of(model, cfg)
    return model
