"""The feedforward plan (eq. 17-18): feedforward inputs u_ff and the nominal state theta_ref along them.

:func:`twin.control.feedforward.solve_feedforward` makes a :class:`FeedforwardPlan`; the LQG
feedback (:mod:`twin.control.lqg`) follows it.

Example
-------
>>> import numpy as np
>>> plan = FeedforwardPlan(t=np.array([0.0, 0.1, 0.2]), u_ff=np.ones((2, 1)), theta_ref=np.zeros((3, 1)),
...                        T_ref=np.zeros(3), T_mean=np.zeros(3), status="test", iterations=0, solve_s=0.0,
...                        success=True)
>>> plan.n_steps, plan.index_at(0.2), plan.sample(5)[0].tolist()   # held beyond the horizon
(2, 2, [1.0])
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.model.dynamics import DiscreteDynamics

Array = NDArray[np.float64]


#: IPOPT's return statuses in words (what a run's events say about a re-plan)
_STATUS_WORDS = {
    "Solve_Succeeded": "solved",
    "Solved_To_Acceptable_Level": "solved to a looser tolerance",
    "Maximum_Iterations_Exceeded": "stopped at the iteration limit, the best plan found is used",
    "Maximum_CpuTime_Exceeded": "stopped at the time limit, the best plan found is used",
    "Maximum_WallTime_Exceeded": "stopped at the time limit, the best plan found is used",
    "Infeasible_Problem_Detected": "no plan meets the constraints, the closest one is used",
    "Restoration_Failed": "the solver got stuck, the best plan found is used",
    "Error_In_Step_Computation": "the solver got stuck, the best plan found is used",
    "Search_Direction_Becomes_Too_Small": "solved (no further progress possible)",
}


def plain_status(status: str) -> str:
    """A plan's status in words for the run's events: IPOPT's return status translated, another source
    of a plan (e.g. ``"test"``) as it is.

    >>> plain_status("Solve_Succeeded"), plain_status("Maximum_Iterations_Exceeded")[:30]
    ('solved', 'stopped at the iteration limit')
    """
    if status in _STATUS_WORDS:
        return _STATUS_WORDS[status]
    return status.replace("_", " ").lower() if "_" in status else status


class FeedforwardError(RuntimeError):
    """IPOPT did not solve the feedforward OCP; ``status`` holds its return status."""

    def __init__(self, message: str, status: str) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class FeedforwardPlan:
    """Feedforward inputs and the nominal reference state along them (eq. 17, section 4).

    Sample j of the plan is at run time ``t[j] = t0 + j t_s``.

    Attributes
    ----------
    t : array (N + 1,)
        Run times (s) of the samples 0..N.
    u_ff : array (N, m)
        Feedforward group fractions u_ff,j, held over [t_j, t_j+1) (eq. 18).
    theta_ref : array (N + 1, n)
        Nominal model state (K) under u_ff from the plan's initial state (eq. 12a, w = 0).
    T_ref : array (N + 1,)
        Requested fillet mean temperature T_ref,j (K) at ``t``.
    T_mean : array (N + 1,)
        Fillet mean of the nominal state, c_m^T theta_ref,j (K) (eq. 19).
    status : str
        IPOPT return status (``"Solve_Succeeded"`` ...) or the name of the source of the plan.
    iterations : int
        IPOPT iterations.
    solve_s : float
        Wall time of the whole plan (OCP set-up, solve, fine simulation) (s).
    success : bool
        Whether the solver reported success.
    u_c : array (m,) or None
        Constant power distribution of eq. (18), max(u_c) = 1 (parametrized OCP), else None.
    v : array (N,) or None
        Scalar amplification v_j of eq. (18) at the samples (parametrized OCP), else None.
    objective : float
        Cost (20a) of the fine-grid plan, per sample: mean of g0 e_j^2 + g1 kappa_j (K^2).
    warm : dict
        Solver data to warm-start a later OCP (knot times, decision values).
    """

    t: Array
    u_ff: Array
    theta_ref: Array
    T_ref: Array
    T_mean: Array
    status: str
    iterations: int
    solve_s: float
    success: bool
    u_c: Array | None = None
    v: Array | None = None
    objective: float = float("nan")
    warm: dict[str, Any] = field(default_factory=dict)

    @property
    def t0(self) -> float:
        """Run time (s) of the first sample."""
        return float(self.t[0])

    @property
    def t_s(self) -> float:
        """Sampling time (s)."""
        return float(self.t[1] - self.t[0])

    @property
    def n_steps(self) -> int:
        """N, the number of input samples."""
        return int(self.u_ff.shape[0])

    @property
    def max_mean_error(self) -> float:
        """max_j |c_m^T theta_ref,j - T_ref,j| (K): how well the nominal plan tracks T_ref."""
        return float(np.max(np.abs(self.T_mean - self.T_ref)))

    def index_at(self, t: float) -> int:
        """Sample index j of run time ``t`` (s) relative to the plan start (may be >= N)."""
        return int(round((t - self.t0) / self.t_s))

    def sample(self, j: int) -> tuple[Array, Array, float]:
        """(u_ff,j, theta_ref,j, T_ref,j); beyond the horizon the last values are held."""
        if j < 0:
            raise IndexError(f"sample {j} lies before the plan start")
        ju = min(j, self.n_steps - 1)
        jx = min(j, self.n_steps)
        return self.u_ff[ju], self.theta_ref[jx], float(self.T_ref[jx])

    def shifted(self, dt: float) -> FeedforwardPlan:
        """The same plan starting ``dt`` s later (a re-plan that comes into force after the time it was made
        for: its reference moves with it)."""
        warm = dict(self.warm)
        if "t_knots" in warm:
            warm["t_knots"] = np.asarray(warm["t_knots"], float) + dt
        return replace(self, t=self.t + dt, warm=warm)

    def v_at(self, t: ArrayLike) -> Array:
        """v(t) of the parametrized plan at run times ``t`` (held per OCP interval and outside)."""
        tk = np.asarray(self.warm["t_knots"], float)
        v = np.asarray(self.warm["v"], float)
        k = np.clip(np.searchsorted(tk, np.asarray(t, float), side="right") - 1, 0, len(v) - 1)
        return np.asarray(v[k], float)


def simulate(model: DiscreteDynamics, theta0: ArrayLike, u: ArrayLike) -> Array:
    """theta_0..theta_N of eq. (12a) with w = 0 under the inputs u (N, m); shape (N + 1, n)."""
    uu = np.asarray(u, float)
    out = np.empty((uu.shape[0] + 1, model.n))
    out[0] = np.asarray(theta0, float)
    for j in range(uu.shape[0]):
        out[j + 1] = model.step(out[j], uu[j])
    return out


def saturation(z: ArrayLike) -> Array:
    """sat of eq. (18) for u_max = 1: clip to [0, 1]."""
    return np.clip(np.asarray(z, float), 0.0, 1.0)
