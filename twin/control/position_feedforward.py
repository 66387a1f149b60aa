"""Lamp powers that follow the oscillating specimen: the position's share of the heat input, fed forward.

The plan and the feedback (eqs. 18-29) model an oscillating specimen with the period-averaged exchange
factors of eq. (11).  Under constant lamp powers the real specimen takes up more heat at one end of its
stroke than at the other, so its fillet mean ripples at the oscillation's period; the feedback, tuned for
the plan's slow deviations, sees the ripple only after the fact and barely answers it.  On `default`
(oscillating, seed 3, honest truth) the true fillet mean rippled by +-0.10 % of the setpoint around its
offset, which took the steady error from 0.15 % (the sensors' bias) to 0.27 %.

The position is known ahead (the drive's schedule), and the position-aware model of section 5.2 (the one
the estimator predicts with) gives the fillet mean's rate at the estimate theta_hat, the input u and the
position eta(t_j):

    r(u; w) = c_m^T D(theta_hat) f(theta_hat, u; w, p)                      (eq. 12a, f in K/s)

with the weights w at eta (w(eta)) or averaged over the period (w-bar, eq. 11); D is the temperature-dependent
capacity's scaling when ``[fe] heat_capacity = "temperature"``, p the calibrated parameters.  r is affine
in u, r(u; w(eta)) = a(eta) + b(eta)^T u.  The input is scaled, u' = (1 + lambda) u, so that the specimen
at eta warms as the controller's model expects:

    b(eta)^T (u' - u) = r(u; w-bar) - r(u; w(eta))

Scaling keeps the plan's share between the groups (its homogeneity); a group driven to 0 or 1 is held
there and the others take its part.  lambda is bounded by :data:`MAX_SCALE` (near the start b^T u is
small and the equation asks for large relative changes of small powers).  A fixed specimen has nothing to
compensate (:meth:`PositionFeedforward.of` gives None, the run is unchanged to the bit).

``[control] position_feedforward`` switches it on (the paper's controller has no such term).

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> from twin.model.tables import model_tables
>>> from twin.radiation import radiation_model
>>> from twin.scenario import OscillationSpec
>>> cfg = small_config()
>>> tables = model_tables(cfg, radiation_model(cfg))
>>> ff = PositionFeedforward.of(tables, OscillationSpec(enabled=True, amplitude=0.02, period=4.0), cfg)
>>> theta, u = np.full(tables.n, 900.0), np.full(6, 0.5)
>>> v = ff.apply(theta, u, 0.02)
>>> bool(abs(ff.mean_rate(theta, v, 0.02) - ff.mean_rate(theta, u, None)) < 1e-9)
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.model.parametric import ParametricModel
from twin.model.tables import ModelTables, Parameters
from twin.scenario import OscillationSpec

Array = NDArray[np.float64]

#: the largest relative change of the inputs (|lambda|): a safety bound, not a tuning.  On `default` (oscillating,
#: seed 3) the scale stays within +-4.8 % from t = 30 s on (median 2 %); the bound acts only between 5 and 30 s,
#: where the lamps are nearly off, b^T u is small and unbounded scales of small powers would only add noise.
MAX_SCALE = 0.25


@dataclass(frozen=True, eq=False)
class PositionFeedforward:
    """The input's correction for the specimen's position (module docstring)."""

    aware: ParametricModel  #: the model at eta(t_j) (section 5.2)
    averaged: ParametricModel  #: the controller's model, eq. (11)

    @classmethod
    def of(cls, tables: ModelTables, oscillation: OscillationSpec | None,
           cfg: FurnaceConfig) -> PositionFeedforward | None:
        """The correction for a motion; None for a fixed specimen (nothing to correct)."""
        if oscillation is None or not oscillation.enabled:
            return None
        calibrated, capacity = tuple(cfg.calibration.parameters), cfg.fe.heat_capacity
        return cls(*(ParametricModel(tables, oscillation, motion=m, calibrated=calibrated, heat_capacity=capacity)
                     for m in ("position_aware", "averaged")))

    def mean_rate(self, theta: ArrayLike, u: ArrayLike, eta: float | None, p: Parameters | None = None) -> float:
        """r(u; w) of the module docstring in K/s: at the position eta, or period-averaged (eta None)."""
        model = self.averaged if eta is None else self.aware
        return float(self.aware.c_m @ model.rhs(theta, u, 0.0 if eta is None else eta, p))

    def apply(self, theta: ArrayLike, u: ArrayLike, eta: float, p: Parameters | None = None,
              lamp_gains: ArrayLike | None = None) -> Array:
        """u' for the position eta (module docstring).  ``lamp_gains``: what each group delivers of its input (a
        group the fault detection found failed, 0, takes no part)."""
        uv = np.asarray(u, float)
        g = np.ones(uv.size) if lamp_gains is None else np.asarray(lamp_gains, float)
        delivered = g * uv
        e_at = self.aware.evaluate(theta, delivered, eta, p)
        e_avg = self.averaged.evaluate(theta, delivered, eta, p)
        c = np.asarray(self.aware.c_m, float)
        if e_at.capacity is not None:
            c = c * e_at.capacity[0]
        gap = float(c @ (e_avg.f - e_at.f))  # e.f: constant-capacity f; its rate is D f
        b = (c @ self.aware.input_matrix(eta, p)) * g  # (m,) K/s per unit input
        return scaled_inputs(uv, b, gap)


def scaled_inputs(u: Array, b: Array, gap: float, max_scale: float = MAX_SCALE) -> Array:
    """u' = (1 + lambda) u on the groups that can move, b^T (u' - u) = gap, u' in [0, 1] (module docstring).

    A group pushed past a bound is held at it and lambda is solved again on the others; |lambda| <= max_scale.
    """
    v = u.copy()
    held = np.zeros(u.size, bool)
    for _ in range(u.size):
        free = ~held & (u > 0.0)
        denom = float(b[free] @ u[free])
        if denom <= 0.0:
            break
        lam = (gap - float(b[held] @ (v[held] - u[held]))) / denom
        lam = min(max(lam, -max_scale), max_scale)
        v[free] = u[free] * (1.0 + lam)
        out = free & ((v > 1.0) | (v < 0.0))
        if not out.any():
            break
        v[out] = np.clip(v[out], 0.0, 1.0)
        held |= out
    return v
