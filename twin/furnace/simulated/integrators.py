"""Explicit time integration of the plant (eqs. 1-6), with its state carried explicitly.

Each call :func:`advance` integrates from ``state.t`` to ``state.t + dt`` with the input held
(zero-order hold) and returns a new :class:`PlantState`; nothing is kept anywhere else.  The
state holds the temperatures and what the methods carry from one call to the next: the
previous sub-step of the two-step Adams-Bashforth method and the cached Gershgorin bound of
the Jacobian's spectral radius (re-evaluated every 10 sub-steps).

Methods (``Plant(method=...)``):

* ``"ab2"`` (default): two-step Adams-Bashforth, one right-hand side per sub-step, started
  (and restarted when the state carries no history) with a Heun step;
* ``"heun"``, ``"rk4"``: Butcher tableaux below (two and four right-hand sides per sub-step).

The sub-step is 70 % of the method's stability limit on the negative real axis over the
Gershgorin bound, so it is stable for any temperature.  Accuracy (module docstring of
:mod:`twin.furnace.simulated.plant`) is far below the TC noise at one sub-step per t_s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from twin.numerics import heun_step

if TYPE_CHECKING:
    from twin.furnace.simulated.plant import Plant

Array = NDArray[np.float64]

# Butcher tableaux: (a rows, b, c, stability limit on the negative real axis |h lambda|); the
# limits are the textbook values of each method.
TABLEAUX: dict[str, tuple[list[list[float]], list[float], list[float], float]] = {
    "rk4": (
        [[], [0.5], [0.0, 0.5], [0.0, 0.0, 1.0]],
        [1 / 6, 1 / 3, 1 / 3, 1 / 6],
        [0.0, 0.5, 0.5, 1.0],
        2.785,
    ),
    "heun": ([[], [1.0]], [0.5, 0.5], [0.0, 1.0], 2.0),
}
METHODS = ("ab2", *TABLEAUX)
STABILITY_MARGIN = 0.7  # use 70 % of the stability limit (Gershgorin bounds are not tight in T)
AB2_LIMIT = 1.0  # two-step Adams-Bashforth: stable for -1 < h lambda < 0 on the real axis
RHO_REFRESH = 10  # sub-steps between two evaluations of the Gershgorin bound


@dataclass(frozen=True)
class AB2History:
    """The previous Adams-Bashforth sub-step: its non-lamp heat flow, capacities, position, length, and
    the lamp heat flow with the inputs it was computed for (W, J/K, m, s)."""

    Q_other: Array
    C: Array
    eta: float
    h: float
    Q_lamps: Array
    v1: Array
    per_lamp: bool


@dataclass(frozen=True)
class PlantState:
    """The plant at time ``t``: cell temperatures ``T`` (N_s,) in K and the integrator's memory.

    ``history`` (AB2 only) is used only by the call that continues from this state;
    ``rho`` (1/s) is the cached Gershgorin bound, ``rho_age`` its age in sub-steps.
    """

    T: Array
    t: float = 0.0
    history: AB2History | None = None
    rho: float = math.inf
    rho_age: int = 0

    def restarted(self) -> PlantState:
        """The same temperatures without integrator memory (after a jump in the motion or the state)."""
        return replace(self, history=None, rho=math.inf, rho_age=0)


def _substep(plant: Plant, T: Array, f: Array, remaining: float, limit: float, rho: float, age: int,
             max_substep: float | None) -> tuple[float, float, int]:
    """Sub-step h (s) that covers ``remaining`` in equal stable pieces, and the updated bound cache."""
    age += 1
    if age >= RHO_REFRESH or remaining * rho > 0.5 * STABILITY_MARGIN * limit:
        rho, age = plant.spectral_radius_bound(T, f), 0
    h_max = STABILITY_MARGIN * limit / rho
    if max_substep is not None:
        h_max = min(h_max, max_substep)
    return remaining / max(1, math.ceil(remaining / h_max - 1e-9)), rho, age


def advance(plant: Plant, state: PlantState, v1: Array, per_lamp: bool, dt: float,
            eta_of_t: Callable[[float], float], max_substep: float | None = None) -> PlantState:
    """Integrate ``state`` over dt with the prepared input ``v1`` held (see :meth:`Plant.inputs`)."""
    if dt < 0:
        raise ValueError(f"dt must be >= 0, got {dt}")
    if plant.method == "ab2":
        return _advance_ab2(plant, state, v1, per_lamp, dt, eta_of_t, max_substep)
    return _advance_rk(plant, state, v1, per_lamp, dt, eta_of_t, max_substep)


def _done(t: float, t_end: float) -> bool:
    return t_end - t <= 1e-12 * max(1.0, abs(t_end))


def _advance_rk(plant: Plant, state: PlantState, v: Array, per_lamp: bool, dt: float,
                eta_of_t: Callable[[float], float], max_substep: float | None) -> PlantState:
    A, b, c, limit = TABLEAUX[plant.method]
    T = np.array(state.T, float)
    rho, age = state.rho, state.rho_age
    t, t_end = state.t, state.t + dt
    while not _done(t, t_end):
        k1 = plant.rate(T, v, per_lamp, eta_of_t(t))
        h, rho, age = _substep(plant, T, k1, t_end - t, limit, rho, age, max_substep)
        ks = [k1]
        for i in range(1, len(b)):
            Ti = T.copy()
            for aij, kj in zip(A[i], ks, strict=False):
                if aij != 0.0:
                    Ti += (h * aij) * kj
            ks.append(plant.rate(Ti, v, per_lamp, eta_of_t(t + c[i] * h)))
        for bi, ki in zip(b, ks, strict=True):
            T += (h * bi) * ki
        t += h
    return PlantState(T=T, t=t_end, rho=rho, rho_age=age)


def _advance_ab2(plant: Plant, state: PlantState, v1: Array, per_lamp: bool, dt: float,
                 eta_of_t: Callable[[float], float], max_substep: float | None) -> PlantState:
    """Two-step Adams-Bashforth with one right-hand side per sub-step (variable step).

    T_{n+1} = T_n + h [(1 + r) f_n - r f_{n-1}], r = h / (2 h_prev).  The history f_{n-1} is
    rebuilt for the *current* inputs: the lamp term (cheap, linear in u) is re-evaluated at
    eta_{n-1}, the rest (conduction, losses, P1 T^4) is stored.  So a change of the held input
    between samples costs no accuracy.  Without history a Heun step starts the method.
    """
    T = np.array(state.T, float)
    prev, rho, age = state.history, state.rho, state.rho_age
    t, t_end = state.t, state.t + dt
    while not _done(t, t_end):
        eta_n = eta_of_t(t)
        Q = plant.heat_flow(T, v1, per_lamp, eta_n)
        QL = plant.lamp_heat_flow(v1, per_lamp, eta_n)
        C = plant.heat_capacity(T)
        f = Q / C
        h, rho, age = _substep(plant, T, f, t_end - t, AB2_LIMIT, rho, age, max_substep)
        if prev is None:  # start with Heun
            T_new = heun_step(lambda tt, x: plant.rate(x, v1, per_lamp, eta_of_t(tt)), t, T, h, f0=f)
        else:
            QL_p = prev.Q_lamps
            if per_lamp != prev.per_lamp or not np.array_equal(v1, prev.v1):  # the held input changed
                QL_p = plant.lamp_heat_flow(v1, per_lamp, prev.eta)
            f_p = (prev.Q_other + QL_p) / prev.C
            r = h / (2.0 * prev.h)
            T_new = T + (h * (1.0 + r)) * f - (h * r) * f_p
        prev = AB2History(Q - QL, C, eta_n, h, QL, v1, per_lamp)
        T = T_new
        t += h
    return PlantState(T=T, t=t_end, history=prev, rho=rho, rho_age=age)


def simulate(plant: Plant, T0: Any, u_of_t: Callable[[float], Array], eta_of_t: Callable[[float], float],
             t_end: float, dt: float) -> tuple[Array, Array]:
    """March with sample time dt, u held per sample; times (n,) and states (n, N_s)."""
    n_steps = int(round(t_end / dt))
    ts: Array = np.arange(n_steps + 1, dtype=float) * dt
    out = np.empty((n_steps + 1, plant.n))
    state = plant.start(T0, 0.0)
    out[0] = state.T
    for j in range(n_steps):
        state = plant.advance(state, u_of_t(ts[j]), dt, eta_of_t)
        out[j + 1] = state.T
    return ts, out
