"""Optimal feedforward control (paper section 4.1, eqs. 18-21): the plan u_ff, theta_ref.

(The OCP itself follows in the next commit; this module holds the plan contract.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


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
        Wall time of the solve (s).
    success : bool
        Whether the solver reported success.
    u_c : array (m,) or None
        Constant power distribution of eq. (18) (parametrized OCP), else None.
    v : array (N,) or None
        Scalar amplification v_j of eq. (18) (parametrized OCP), else None.
    warm : dict
        Solver data to warm-start a later OCP (decision vector, multipliers, grid).
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
    warm: dict[str, object] = field(default_factory=dict)

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
