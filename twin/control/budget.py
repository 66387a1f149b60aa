"""What a plan may cost and how it is stopped: wall time, memory and cancellation of a planning job.

The feedforward (:mod:`twin.control.feedforward`) and the LQG design (:mod:`twin.control.lqg`) of a run
are the only numerics whose cost depends on what a user asks for (the planning horizon).  A
:class:`PlanBudget` travels with each planning job:

* ``max_wall_s``: wall time the whole plan (OCP and gains) may take.  Estimated before solving
  (:func:`estimate_plan`, from the model's own Jacobian time); a plan estimated above it is refused
  (:class:`PlanTooLarge`); the solve stops when it is reached all the same (IPOPT's wall-time limit and
  the checks below).
* ``max_memory_mb``: memory of the plan's largest arrays (:func:`estimate_plan`); above it is refused.
* ``cancel``: a :class:`CancelToken` (or any ``threading.Event``) checked at every knot of every sweep
  of the OCP and every few samples of the gains, so a Stop, a newer change or a shutdown ends the job
  within milliseconds (:class:`PlanCancelled`).

Example
-------
>>> budget = PlanBudget(max_wall_s=60.0, max_memory_mb=1024.0)
>>> child = budget.child()        # a re-plan: cancelled by its own token or by the run's
>>> child.cancel.cancel()
>>> child.cancelled, budget.cancelled
(True, False)
>>> est = PlanEstimate(horizon_s=144.0, knots=144, substeps=144, samples=1440, n=105, m=6, sweep_s=0.5,
...                    jacobian_s=3e-4, riccati_s=2e-4)      # the default run, a sweep of 0.5 s
>>> round(est.memory_mb), round(est.seconds, 1)
(56, 15.3)
>>> budget.problem(est) is None
True
>>> print(budget.problem(PlanEstimate(4320.0, 240, 1440, 43200, 105, 6, sweep_s=3.0)))  # doctest: +NORMALIZE_WHITESPACE
a plan over 4320 s (240 knots, 43200 samples) would take about 90 s to compute on this machine now,
this server allows 60 s: shorten the run or the transition
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Protocol


class PlanCancelled(RuntimeError):
    """The planning job was cancelled (Stop, a newer change, shutdown); nothing was installed."""


class PlanTooLarge(ValueError):
    """A plan cannot be made within the stated time or memory; the message says which and why."""


class _Flag(Protocol):
    def is_set(self) -> bool: ...


class CancelToken:
    """Set by :meth:`cancel`, or when any of its ``sources`` (events, other tokens) is set."""

    def __init__(self, *sources: _Flag) -> None:
        self._own = threading.Event()
        self._sources = sources

    def cancel(self) -> None:
        self._own.set()

    def is_set(self) -> bool:
        return self._own.is_set() or any(s.is_set() for s in self._sources)


#: Sweeps (cost, gradient, Hessian) of a typical OCP solve: measured 10-41 on the default and the small
#: furnace (30-40 IPOPT iterations; warm starts and short horizons need fewer).  The cost-only simulations
#: (about as many) cost a small fraction of a sweep.  The estimate is of a typical solve; the wall-time
#: limit stops an atypical one.
TYPICAL_SWEEPS = 30
#: Held Jacobians of the LQG design (twin.control.replan.JACOBIAN_EVERY)
GAINS_JACOBIAN_EVERY = 10
#: Dense float64 (n_params)^2 matrices of a sweep: the Gauss-Newton Hessian, the input curvature, IPOPT's
#: copy and its factor
HESSIAN_COPIES = 4


@dataclass(frozen=True)
class PlanEstimate:
    """Size of one plan (horizon, knots K, Heun substeps, fine samples N of an n-state, m-input model) and
    what it costs.

    The time comes from the real code on this machine now (so it follows its load): ``sweep_s`` is one
    sweep of this very OCP (cost, gradient and Hessian over the whole horizon: :meth:`twin.control.
    ocp_grid.PlanGrid.estimate` with ``timed=True``), ``jacobian_s`` a Jacobian pair of the model and
    ``riccati_s`` one step of the gains' recursion.  ``None`` until measured.
    """

    horizon_s: float
    knots: int
    substeps: int  # Heun substeps over the horizon (knots x substeps per knot)
    samples: int  # fine samples of the plan (and of its gains)
    n: int
    m: int
    sweep_s: float | None = None
    jacobian_s: float = 0.0
    riccati_s: float = 0.0

    @property
    def memory_mb(self) -> float:
        """Largest arrays (float64): the sweep's residual Jacobian (K (n+1) x (m+K)) and Hessians, its stored
        stage Jacobians (4 per substep), the plan's states and the gains (N x m x (n+1))."""
        K, n, m, N = self.knots, self.n, self.m, self.samples
        p = m + K
        words = (K * (n + 1) * p + HESSIAN_COPIES * p * p + self.substeps * 2 * (n * n + n * m)
                 + 2 * (N + 1) * n + N * m * (n + 1))
        return 8.0 * words / 1e6

    @property
    def seconds(self) -> float | None:
        """Typical wall time: ``TYPICAL_SWEEPS`` sweeps, then the gains (``None`` if not measured)."""
        if self.sweep_s is None:
            return None
        gains_s = self.samples / GAINS_JACOBIAN_EVERY * self.jacobian_s + self.samples * self.riccati_s
        return TYPICAL_SWEEPS * self.sweep_s + gains_s


#: the wall time a plan of a batch run (a campaign's) may take (s): on a loaded machine a plan that takes 20 s on a
#: quiet one took over 120 s (an oscillating `banded` plan at load 14 stopped after 27 IPOPT iterations and ended the
#: whole campaign); a batch run has nobody waiting for it, so only a plan that does not converge should end it
BATCH_MAX_WALL_S = 1800.0


@dataclass(frozen=True)
class PlanBudget:
    """Limits and the cancel token of one planning job (module docstring)."""

    max_wall_s: float = 120.0
    max_memory_mb: float = math.inf
    cancel: CancelToken = field(default_factory=CancelToken)
    started: float = field(default_factory=time.monotonic)

    @classmethod
    def of(cls, max_wall_s: float, max_memory_mb: float, *stop: _Flag) -> PlanBudget:
        """A budget cancelled when any of ``stop`` is set (e.g. a run's stop event)."""
        return cls(max_wall_s, max_memory_mb, CancelToken(*stop))

    def child(self) -> PlanBudget:
        """The same limits, a fresh clock, and a token of its own that this one's also sets."""
        return PlanBudget(self.max_wall_s, self.max_memory_mb, CancelToken(self.cancel))

    @property
    def cancelled(self) -> bool:
        return self.cancel.is_set()

    @property
    def elapsed_s(self) -> float:
        return time.monotonic() - self.started

    @property
    def remaining_s(self) -> float:
        return max(self.max_wall_s - self.elapsed_s, 0.0)

    @property
    def spent(self) -> bool:
        """The wall time is used up (:meth:`check` raises :class:`PlanTooLarge`)."""
        return self.elapsed_s > self.max_wall_s

    @property
    def over(self) -> bool:
        """Cancelled or spent: :meth:`check` would raise (a solver's iteration callback asks this)."""
        return self.cancel.is_set() or self.spent

    def check(self, what: str = "planning") -> None:
        """Raise :class:`PlanCancelled` if cancelled, :class:`PlanTooLarge` if the wall time is spent."""
        if self.cancel.is_set():
            raise PlanCancelled(f"{what} was cancelled")
        if self.spent:
            raise PlanTooLarge(f"{what} did not finish within {self.max_wall_s:g} s (this server's plan time limit)")

    def check_cancel(self, what: str = "planning") -> None:
        """Raise :class:`PlanCancelled` if cancelled (the wall time is not looked at)."""
        if self.cancel.is_set():
            raise PlanCancelled(f"{what} was cancelled")

    def problem(self, est: PlanEstimate) -> str | None:
        """Why a plan of this size cannot be made within the budget, or ``None``."""
        what = (f"a plan over {est.horizon_s:.0f} s ({est.knots} knots, {est.samples} samples)")
        if est.memory_mb > self.max_memory_mb:
            return (f"{what} needs about {est.memory_mb:.0f} MB, this server allows {self.max_memory_mb:g} MB: "
                    f"shorten the run or the transition")
        if est.seconds is not None and est.seconds > self.max_wall_s:
            return (f"{what} would take about {est.seconds:.0f} s to compute on this machine now, this server "
                    f"allows {self.max_wall_s:g} s: shorten the run or the transition")
        return None

    def refuse_if_too_large(self, est: PlanEstimate) -> None:
        problem = self.problem(est)
        if problem is not None:
            raise PlanTooLarge(problem)
