"""Reference trajectories T_ref(t) of the fillet mean temperature (paper section 5, Fig. 3).

Two kinds, both C1 in time and constant after their last value:

* :class:`twin.scenario.TransitionReference` -- the paper's transition from the
  initial mean temperature to the setpoint within ``t_E`` (Fig. 3).  The paper only
  says "piecewise polynomial C1-function"; we use the cubic Hermite step
  ``T0 + (T_E - T0) (3 s^2 - 2 s^3)``, ``s = t / t_E``, which has zero slope at both
  ends, so joined with the constants before 0 and after ``t_E`` it is C1.
* :class:`twin.scenario.PointsReference` -- user-given (time, temperature) points
  joined by a monotone cubic Hermite spline (Fritsch-Carlson slopes, as in PCHIP)
  with zero slope at the first and the last point, so the join with the constant
  parts is C1 as well.  If the first point lies after ``t = 0`` the curve starts at
  the initial mean temperature at ``t = 0``.

Times of a reference are relative to ``t_start`` (the run time at which it takes
effect: 0 at the start of a run, the current time after a re-plan).

Example
-------
>>> from twin.scenario import TransitionReference
>>> ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=120.0), 300.0)
>>> [round(float(v), 1) for v in ref(np.array([0.0, 60.0, 120.0, 240.0]))]
[300.0, 700.0, 1100.0, 1100.0]
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicHermiteSpline, PchipInterpolator

from twin.config import FurnaceConfig
from twin.model.dynamics import DiscreteDynamics
from twin.numerics import damped_newton
from twin.scenario import PointsReference, TransitionReference

log = logging.getLogger(__name__)

Array = NDArray[np.float64]


class ReferenceError(ValueError):
    """A reference trajectory cannot be followed (unreachable temperature, bad times)."""


@dataclass(frozen=True)
class ReferenceTrajectory:
    """A C1 reference T_ref(t) in K, callable on an array of run times in s.

    Attributes
    ----------
    t_start : float
        Run time (s) at which the reference takes effect; before it T_ref = ``T_initial``.
    t_end : float
        Run time (s) from which T_ref is constant (``t_start + t_E`` for a transition).
    T_initial, T_final : float
        T_ref(t_start) and T_ref(t >= t_end) in K.
    """

    t_start: float
    t_end: float
    T_initial: float
    T_final: float
    _spline: CubicHermiteSpline | None

    def __call__(self, t: ArrayLike) -> Array:
        """T_ref(t) in K for run times ``t`` (s), any shape."""
        tt = np.asarray(t, dtype=float)
        if self._spline is None:
            return np.full_like(tt, self.T_final)
        tc = np.clip(tt, self.t_start, self.t_end)
        out = np.asarray(self._spline(tc), dtype=float)
        # exact constants outside the transition (the spline's end values carry round-off)
        out = np.where(tt <= self.t_start, self.T_initial, out)
        return np.where(tt >= self.t_end, self.T_final, out)

    def rate(self, t: ArrayLike) -> Array:
        """dT_ref/dt in K/s (zero outside [t_start, t_end])."""
        tt = np.asarray(t, dtype=float)
        if self._spline is None:
            return np.zeros_like(tt)
        inside = (tt > self.t_start) & (tt < self.t_end)
        d = np.asarray(self._spline.derivative()(np.clip(tt, self.t_start, self.t_end)), float)
        return np.where(inside, d, 0.0)

    @property
    def transition_time(self) -> float:
        """t_E of the paper: duration of the transition (s), ``t_end - t_start``."""
        return self.t_end - self.t_start


def _check_range(values: list[float], T_range: tuple[float, float] | None, what: str) -> None:
    if T_range is None:
        return
    lo, hi = T_range
    for v in values:
        if not lo <= v <= hi:
            raise ReferenceError(
                f"{what} {v:.1f} K is unreachable: this furnace can hold the fillet mean only "
                f"between {lo:.1f} K and {hi:.1f} K"
            )


def _transition(spec: TransitionReference, T_initial: float, t_start: float) -> ReferenceTrajectory:
    """The paper's C1 transition (Fig. 3) as a cubic Hermite segment with zero end slopes."""
    t_end = t_start + spec.t_E
    spline = CubicHermiteSpline(
        [t_start, t_end], [T_initial, spec.setpoint], [0.0, 0.0], extrapolate=False
    )
    return ReferenceTrajectory(t_start, t_end, T_initial, spec.setpoint, spline)


def _points(spec: PointsReference, T_initial: float, t_start: float) -> ReferenceTrajectory:
    """Monotone C1 interpolation of user points (Fritsch-Carlson slopes, zero end slopes)."""
    ts = [p[0] for p in spec.points]
    Ts = [p[1] for p in spec.points]
    if any(not math.isfinite(v) for v in ts + Ts):
        raise ReferenceError("reference points must be finite numbers")
    if any(b <= a for a, b in zip(ts, ts[1:], strict=False)):
        raise ReferenceError("reference point times must be strictly increasing")
    if ts[0] < 0:
        raise ReferenceError("reference point times must be >= 0 s (relative to the start of the reference)")
    if ts[0] > 0:
        ts = [0.0, *ts]
        Ts = [T_initial, *Ts]
    if len(ts) == 1:
        return ReferenceTrajectory(t_start, t_start, Ts[0], Ts[0], None)
    t_abs = np.asarray(ts, float) + t_start
    T_arr = np.asarray(Ts, float)
    slopes = np.asarray(PchipInterpolator(t_abs, T_arr).derivative()(t_abs), float)
    slopes[0] = 0.0
    slopes[-1] = 0.0
    spline = CubicHermiteSpline(t_abs, T_arr, slopes, extrapolate=False)
    return ReferenceTrajectory(float(t_abs[0]), float(t_abs[-1]), float(T_arr[0]), float(T_arr[-1]), spline)


def reference_trajectory(
    spec: TransitionReference | PointsReference,
    T_initial: float,
    *,
    t_start: float = 0.0,
    T_range: tuple[float, float] | None = None,
) -> ReferenceTrajectory:
    """Build the C1 reference T_ref(t) (K) of the fillet mean temperature.

    Parameters
    ----------
    spec : TransitionReference | PointsReference
        What the user asked for (``twin.scenario``).
    T_initial : float
        Fillet mean temperature (K) at ``t_start``; start of the transition (paper, section 5).
    t_start : float
        Run time (s) at which the reference begins; point times are relative to it.
    T_range : (float, float), optional
        Fillet mean temperatures (K) the furnace can hold (see :func:`reachable_range`).
        Every requested temperature must lie inside, else :class:`ReferenceError`.

    Returns
    -------
    ReferenceTrajectory
        Callable ``ref(t) -> T_ref`` (K) on arrays of run times (s).

    Raises
    ------
    ReferenceError
        (a ``ValueError``) for unreachable temperatures or non-increasing times.
    """
    if not math.isfinite(T_initial) or T_initial <= 0:
        raise ReferenceError(f"initial mean temperature must be a positive number of kelvin, got {T_initial}")
    if not math.isfinite(t_start) or t_start < 0:
        raise ReferenceError(f"t_start must be a non-negative time in s, got {t_start}")
    if isinstance(spec, TransitionReference):
        _check_range([spec.setpoint], T_range, "setpoint")
        ref = _transition(spec, float(T_initial), float(t_start))
    elif isinstance(spec, PointsReference):
        _check_range([p[1] for p in spec.points], T_range, "reference point temperature")
        ref = _points(spec, float(T_initial), float(t_start))
    else:
        raise TypeError(f"unknown reference type {type(spec).__name__}")
    log.debug("reference from %.1f K at %.1f s to %.1f K at %.1f s", ref.T_initial, ref.t_start,
              ref.T_final, ref.t_end)
    return ref


def coldest_surrounding(cfg: FurnaceConfig) -> float:
    """Lowest temperature (K) of anything the specimen exchanges heat with.

    With all lamps off the specimen cools towards its surroundings (walls, reflectors,
    holders, inert gas; eqs. 3, 4, 6), so no mean temperature below this is reachable.
    """
    return min(
        cfg.housing.temperature,
        cfg.reflector.temperature,
        cfg.holders.temperature_upper,
        cfg.holders.temperature_lower,
        cfg.inert_gas.temperature_top,
        cfg.inert_gas.temperature_bottom,
    )


def steady_state(model: DiscreteDynamics, u: ArrayLike, theta_guess: ArrayLike, *, tol: float = 1e-6,
                 max_iter: int = 50) -> Array:
    """Fixed point theta = F(theta, u) of the discrete model (eq. 12a) by Newton's method.

    Parameters
    ----------
    model : DiscreteModel
        ``step`` and ``jac_theta`` as in docs/interfaces.md.
    u : array (m,)
        Constant group fractions.
    theta_guess : array (n,)
        Start of the iteration (K).
    tol : float
        Stop when the Newton step is below ``tol`` K in every node.

    Raises
    ------
    ReferenceError
        If Newton does not converge in ``max_iter`` iterations.
    """
    uu = np.asarray(u, float)
    eye = np.eye(model.n)
    # a model with c_p(T) (twin.control.plan_model.CapacityModel) has the steady states of its base model, where
    # Newton does not meet the slopes of the c_p table's Curie peak
    model = getattr(model, "base", model)
    # steps larger than 500 K in any node are damped: the T^4 terms make far Newton steps overshoot
    return damped_newton(
        lambda th: np.asarray(model.step(th, uu), float) - th,
        lambda th: np.asarray(model.jac_theta(th, uu), float) - eye,
        np.asarray(theta_guess, float), tol=tol, max_iter=max_iter, max_step=500.0,
        what="steady state of the model", error=ReferenceError,
    )


def reachable_range(model: DiscreteDynamics, cfg: FurnaceConfig) -> tuple[float, float]:
    """Fillet mean temperatures (K) the furnace can hold: (coldest surrounding, full power).

    The upper end is c_m^T theta_s (eq. 19) of the model's steady state with every
    group at u = 1 (u_max); the lower end is :func:`coldest_surrounding`.
    """
    theta0 = np.full(model.n, cfg.fe.reference_temperature)
    theta_max = steady_state(model, np.ones(model.m), theta0)
    return coldest_surrounding(cfg), float(model.c_m @ theta_max)
