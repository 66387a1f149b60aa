"""Small dense convex QPs for the MPC (:mod:`twin.control.mpc`), solved by OSQP or qpOASES.

    min_z  1/2 z^T H z + g^T z   s.t.  lbx <= z <= ubx,  lba <= A z <= uba

The MPC's QP keeps its size and sparsity from one sample to the next (only the numbers change), so a
solver is set up once and then updated and warm-started each sample.

Backends (``[control] mpc_solver``), chosen by measurement (docs/control.md, "QP solver"):

* ``"osqp"``: OSQP (Stellato et al. 2020), ADMM with a cached factorisation; warm-started from the last
  solution; ``polish`` makes the active set exact.
* ``"qpoases"``: qpOASES (Ferreau et al. 2014), an online active-set method, through CasADi's ``conic``.

Both are checked against scipy's SLSQP on the same problem in the tests.

Example
-------
>>> import numpy as np
>>> qp = QP(H=np.eye(2), g=np.array([-2.0, 0.5]), A=np.zeros((0, 2)), lba=np.zeros(0), uba=np.zeros(0),
...         lbx=np.zeros(2), ubx=np.ones(2))
>>> sol = make_solver("osqp").solve(qp)
>>> sol.ok, np.round(sol.z, 4).tolist()      # min (z - (2, -0.5))^2 / 2 on the unit box
(True, [1.0, 0.0])
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np
import scipy.sparse
from numpy.typing import NDArray

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

SolverName = Literal["osqp", "qpoases"]


@dataclass(frozen=True)
class QP:
    """A convex QP in the form of the module docstring (H symmetric positive semidefinite)."""

    H: Array
    g: Array
    A: Array
    lba: Array
    uba: Array
    lbx: Array
    ubx: Array


@dataclass(frozen=True)
class QPResult:
    z: Array
    ok: bool
    status: str
    iterations: int
    solve_ms: float


class QPSolver(Protocol):
    def solve(self, qp: QP) -> QPResult: ...


def _pattern(mask: Array) -> tuple[scipy.sparse.csc_matrix, Array, Array]:
    """A csc matrix of ones on ``mask`` and the (row, column) of each stored entry, in storage order."""
    S = scipy.sparse.csc_matrix(mask.astype(float))
    S.sort_indices()
    cols = np.repeat(np.arange(S.shape[1]), np.diff(S.indptr))
    return S, S.indices.copy(), cols


class OSQPSolver:
    """OSQP, set up at the first problem and updated (values only) and warm-started afterwards.

    H's upper triangle and A are stored dense (every entry structural), so any problem of the same size
    can update the numbers of the set-up one.
    """

    def __init__(self, eps: float = 1e-7, max_iter: int = 4000) -> None:
        self.eps, self.max_iter = eps, max_iter
        self._solver: Any = None
        self._shape: tuple[int, int] | None = None

    def _setup(self, nz: int, na: int) -> None:
        import osqp

        P, self._p_rows, self._p_cols = _pattern(np.triu(np.ones((nz, nz), bool)))
        mask = np.vstack([np.eye(nz, dtype=bool), np.ones((na, nz), bool)])
        Acon, self._a_rows, self._a_cols = _pattern(mask)
        self._solver = osqp.OSQP()
        self._solver.setup(P=P, q=np.zeros(nz), A=Acon, l=-np.ones(nz + na), u=np.ones(nz + na),
                           eps_abs=self.eps, eps_rel=self.eps, max_iter=self.max_iter, polishing=False,
                           verbose=False, warm_starting=True, adaptive_rho=True)
        self._shape = (nz, na)

    def solve(self, qp: QP) -> QPResult:
        t0 = time.perf_counter()
        nz, na = qp.H.shape[0], qp.A.shape[0]
        if self._shape != (nz, na):
            self._setup(nz, na)
        Hs = 0.5 * (qp.H + qp.H.T)
        A_full = np.vstack([np.eye(nz), qp.A])
        self._solver.update(Px=Hs[self._p_rows, self._p_cols], Ax=A_full[self._a_rows, self._a_cols], q=qp.g,
                            l=np.concatenate([qp.lbx, qp.lba]), u=np.concatenate([qp.ubx, qp.uba]))
        res = self._solver.solve(raise_error=False)
        status = str(res.info.status)
        ok = status in ("solved", "solved inaccurate") and res.x is not None and bool(np.all(np.isfinite(res.x)))
        z = np.asarray(res.x, float) if ok else np.full(nz, np.nan)
        if ok:  # OSQP meets the bounds to its tolerance: the last 1e-7 are clipped
            z = np.clip(z, qp.lbx, qp.ubx)
        return QPResult(z, ok, status, int(res.info.iter), 1000.0 * (time.perf_counter() - t0))


class QpOASESSolver:
    """qpOASES through CasADi's ``conic`` (dense; set up once per problem size)."""

    def __init__(self) -> None:
        self._solver: Any = None
        self._shape: tuple[int, int] | None = None

    def solve(self, qp: QP) -> QPResult:
        import casadi as ca

        t0 = time.perf_counter()
        nz, na = qp.H.shape[0], qp.A.shape[0]
        if self._shape != (nz, na):
            Hsp = ca.Sparsity.dense(nz, nz)
            Asp = ca.Sparsity.dense(na, nz)
            self._solver = ca.conic("mpc", "qpoases", {"h": Hsp, "a": Asp},
                                    {"printLevel": "none", "error_on_fail": False, "sparse": False})
            self._shape = (nz, na)
        out = self._solver(h=0.5 * (qp.H + qp.H.T), g=qp.g, a=qp.A, lbx=qp.lbx, ubx=qp.ubx, lba=qp.lba,
                           uba=qp.uba)
        stats = self._solver.stats()
        ok = bool(stats.get("success", False))
        z = np.asarray(out["x"], float).ravel()
        return QPResult(z if ok else np.full(nz, np.nan), ok, str(stats.get("return_status", "")),
                        int(stats.get("iter_count", -1) or -1), 1000.0 * (time.perf_counter() - t0))


def make_solver(name: str) -> QPSolver:
    """A QP solver by name (``"osqp"`` or ``"qpoases"``)."""
    if name == "osqp":
        return OSQPSolver()
    if name == "qpoases":
        return QpOASESSolver()
    raise ValueError(f"unknown QP solver {name!r}: 'osqp' or 'qpoases'")
