"""Steady group powers that hold the fillet mean at a setpoint (calibration and initial plans).

For constant inputs u the plant (eqs. 1-4, 6) settles where its heat balance vanishes,
Q(T, u) = 0; with oscillation, the time-averaged model (eq. 11) with period-averaged
P1, P2 gives the quasi-steady field around which the plant oscillates.  The steady field
is found by Newton's method with the analytic Jacobian (:meth:`twin.furnace.simulated.plant.Plant.steady_state`)
and its sensitivity to u by the implicit function theorem, dT/du = -(dQ/dT)^-1 dQ/du.

:func:`steady_powers` finds group fractions 0 <= u <= 1 that put the fillet mean at
``T_mean`` and minimise the fillet's spread: the bounded least-squares problem

    min_u  sum_{k in fillet} (T_k(u) - T_mean)^2 / N_f  +  w_m^2 (mean_f(T(u)) - T_mean)^2,

(in units of T_mean), which with the heavy mean weight w_m is "mean at the setpoint,
smallest RMS deviation".  :func:`uniform_scale` is the simpler variant: one common fraction
for all groups.

Example
-------
>>> from twin.config import small_config
>>> from twin.furnace.simulated.plant import Plant
>>> from twin.radiation import radiation_model
>>> sp = steady_powers(Plant(small_config(), radiation_model(small_config())))
>>> round(sp.fillet_mean), bool(0.0 <= sp.u.min() and sp.u.max() <= 1.0)
(1100, True)
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from twin.furnace.simulated.plant import Plant
from twin.physics.motion import average_weights
from twin.scenario import OscillationSpec

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

MEAN_WEIGHT = 30.0  # w_m: a 0.1 K mean error costs as much as a 3 K RMS spread


@dataclass(frozen=True)
class SteadyPowers:
    """Result of :func:`steady_powers` / :func:`uniform_scale`.

    Attributes
    ----------
    u : (6,) group fractions of u_max
    T : (N_s,) steady field in K (of the time-averaged model when oscillating)
    fillet_mean : K
    inhomogeneity : max over the fillet |T - mean| / T_mean (dimensionless)
    saturated : some group sits at a bound (0 or 1)
    """

    u: Array
    T: Array
    fillet_mean: float
    inhomogeneity: float
    saturated: bool


def steady_weights(plant: Plant, oscillation: OscillationSpec | None) -> Array:
    """Hat weights of the table positions: eta = 0, or period-averaged (eq. 11b) when oscillating."""
    return np.asarray(average_weights(plant.eta_nodes, oscillation), float)


def _result(plant: Plant, u: Array, T: Array, T_mean: float) -> SteadyPowers:
    return SteadyPowers(
        u=u,
        T=T,
        fillet_mean=plant.fillet_mean(T),
        inhomogeneity=plant.fillet_inhomogeneity(T) / T_mean,
        saturated=bool(np.any(u <= 1e-6) or np.any(u >= 1 - 1e-6)),
    )


def uniform_scale(
    plant: Plant,
    T_mean: float = 1100.0,
    oscillation: OscillationSpec | None = None,
    distribution: ArrayLike | None = None,
) -> SteadyPowers:
    """u = s * distribution (default all ones) with the scalar s that puts the fillet mean at T_mean.

    Newton on s with d(mean)/ds from the steady sensitivity; s is not clipped, so s > 1
    (the furnace cannot reach T_mean with this distribution) shows in ``u``.
    """
    if plant.radiation is None:
        raise ValueError("steady powers need the radiation model (the lamps are the only heat source)")
    d = np.ones(plant.n_groups) if distribution is None else np.asarray(distribution, float)
    w = steady_weights(plant, oscillation)
    s, T = 0.5 / max(float(d.max()), 1e-12), None
    for _ in range(40):
        T = plant.steady_state(np.clip(s * d, 0.0, 1.0), w, T)
        err = plant.fillet_mean(T) - T_mean
        if abs(err) < 1e-6:
            break
        dmean = float(plant.fillet.mean(plant.steady_sensitivity(T, w) @ d))
        s -= err / dmean
        if s * float(d.max()) > 1.0:
            raise ValueError(f"T_mean = {T_mean} K needs more than u_max with this distribution")
    assert T is not None
    return _result(plant, s * d, T, T_mean)


def steady_powers(
    plant: Plant,
    T_mean: float = 1100.0,
    oscillation: OscillationSpec | None = None,
    *,
    u0: ArrayLike | None = None,
) -> SteadyPowers:
    """Group fractions 0 <= u <= 1 holding the fillet mean at T_mean with the smallest spread.

    Parameters
    ----------
    plant : the full-order plant (with radiation)
    T_mean : fillet mean setpoint in K
    oscillation : None / disabled = fixed specimen at eta = 0; enabled = time-averaged model
    u0 : start of the search (default: the uniform scale)

    Returns
    -------
    SteadyPowers; ``fillet_mean`` shows whether T_mean was reachable within the bounds.
    """
    return _steady_powers(plant, T_mean, oscillation, u0)


def _steady_powers(
    plant: Plant, T_mean: float, oscillation: OscillationSpec | None, u0: ArrayLike | None
) -> SteadyPowers:
    start = uniform_scale(plant, T_mean, oscillation) if u0 is None else None
    x0 = np.clip(start.u if start is not None else np.asarray(u0, float), 0.0, 1.0)
    w = steady_weights(plant, oscillation)
    mask = plant.fillet_mask  # the cells of the closed fillet: their spread is minimised
    nf = int(mask.sum())
    cache: dict[str, Array] = {"T": start.T if start is not None else plant.steady_state(x0, w)}

    def field(u: Array) -> Array:
        if "u" not in cache or not np.array_equal(cache["u"], u):
            cache["T"] = plant.steady_state(u, w, cache["T"])
            cache["u"] = u.copy()
        return cache["T"]

    def residuals(u: Array) -> Array:
        T = field(u)
        spread = (T[mask] - T_mean) / (T_mean * np.sqrt(nf))
        return np.concatenate([spread, [MEAN_WEIGHT * (plant.fillet_mean(T) - T_mean) / T_mean]])

    def jac(u: Array) -> Array:
        S = plant.steady_sensitivity(field(u), w)  # (N_s, 6)
        return np.vstack([S[mask] / (T_mean * np.sqrt(nf)), MEAN_WEIGHT * (plant.fillet.flat_weights @ S) / T_mean])

    sol = least_squares(residuals, x0, jac=jac, bounds=(0.0, 1.0), method="trf", xtol=1e-10, ftol=1e-12)
    u = np.clip(sol.x, 0.0, 1.0)
    T = field(u)
    log.info(
        "steady_powers: u = %s, fillet mean %.2f K, inhomogeneity %.2f %% (%s)",
        np.array2string(u, precision=3),
        plant.fillet_mean(T),
        100 * plant.fillet_inhomogeneity(T) / T_mean,
        sol.message,
    )
    return _result(plant, u, T, T_mean)


@dataclass(frozen=True)
class PeriodicInhomogeneity:
    """Inhomogeneity of the plant over its last simulated oscillation period (relative to T_mean)."""

    max: float
    mean: float
    fillet_mean_min: float
    fillet_mean_max: float
    T_end: Array


def periodic_inhomogeneity(
    plant: Plant,
    u: ArrayLike,
    oscillation: OscillationSpec,
    T0: ArrayLike,
    T_mean: float = 1100.0,
    periods: int = 6,
) -> PeriodicInhomogeneity:
    """Run the plant with eta(t) from T0 for ``periods`` periods; statistics of the last one.

    The inhomogeneity at each sample is max over the closed fillet's cells |T - fillet mean| / T_mean.
    """
    from twin.physics.motion import eta_function

    eta = eta_function(oscillation)
    dt = plant.cfg.sampling.t_s
    n_period = int(round(oscillation.period / dt))
    v = np.asarray(u, float)
    state = plant.start(T0, 0.0)
    inh, means = [], []
    for j in range(periods * n_period):
        state = plant.advance(state, v, dt, eta)
        if j >= (periods - 1) * n_period:
            inh.append(plant.fillet_inhomogeneity(state.T) / T_mean)
            means.append(plant.fillet_mean(state.T))
    T = state.T
    return PeriodicInhomogeneity(
        max=float(np.max(inh)),
        mean=float(np.mean(inh)),
        fillet_mean_min=float(np.min(means)),
        fillet_mean_max=float(np.max(means)),
        T_end=T,
    )
