"""Model predictive feedback on the deviation from the feedforward (the constraint-aware twin of the LQG).

The LQG (:mod:`twin.control.lqg`, eqs. 22-29) computes Delta u_j = K_j e_j and then clips
u_ff,j + Delta u_j to [0, 1] group by group: a group at full power loses its share of the correction and
the others do not take it over.  The MPC solves, every sample, the LQG's own problem (27) over a horizon
of a few seconds *with* the bounds:

    min  sum_{k=0}^{H-1} ( e_k^T Q e_k + r0 |Delta u_k|^2 ) + e_H^T P_{j+H} e_H
    s.t. e_{k+1} = Phi~_{j+k} e_k + Gamma~_{j+k} Delta u_k          (eq. 24, the design's linearisation)
         0 <= u_ff,j+k + Delta u_k <= 1                               (input bounds)
         |u_j - u_{j-1}| <= rate t_s, and between the moves            (rate bounds)

with e = [theta_hat - theta_ref ; e_I] (eq. 24), Q of eq. (28), and the terminal cost P_{j+H} the
cost-to-go of the LQG's Riccati recursion (29) (P_S beyond the plan).  Without active bounds and with one
move per sample its first move is exactly the LQG's K_j e_j (a test checks it); with bounds, a group at
u = 1 or 0 hands its part to the groups that still have room.  Offset-free as the LQG: the integral state
e_I is part of e, integrated (eq. 22) with the LQG's anti-windup.

Moves are blocked to keep the QP small: the first over one sample, the rest of the horizon split evenly
among ``mpc_moves - 1`` blocks.  The condensed QP (inputs only) is solved by OSQP
(:mod:`twin.control.qp`); a QP that fails is solved again without the rate bounds between the moves, and if
that fails too the sample takes the LQG's input (counted in :attr:`MPCController.fallbacks`).

The horizon ends at a sample where the design kept P_j (a multiple of its ``jacobian_every``), at most
``mpc_horizon`` seconds ahead.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.control.lqg import (
    Controller,
    ControlOutput,
    Gains,
    IntegratorState,
    anti_windup_delta,
    integrator_delta,
)
from twin.control.plan import FeedforwardPlan
from twin.control.qp import QP, QPSolver, make_solver
from twin.model.dynamics import DiscreteDynamics

log = logging.getLogger(__name__)
Array = NDArray[np.float64]


@dataclass(frozen=True)
class MPCSettings:
    """Horizon (samples, before it is cut to a kept P_j), moves, rate bound per sample (u_max), solver."""

    horizon: int
    moves: int
    rate: float
    solver: str = "osqp"


def move_blocks(H: int, moves: int) -> list[int]:
    """Lengths (samples) of the moves over a horizon of H samples: the first one sample, the rest as even
    as possible.

    >>> move_blocks(30, 5), move_blocks(3, 5), move_blocks(1, 4)
    ([1, 8, 7, 7, 7], [1, 1, 1], [1])
    """
    if H < 1 or moves < 1:
        raise ValueError("the horizon and the number of moves must be >= 1")
    if moves == 1 or H == 1:
        return [H]
    rest, k = H - 1, min(moves - 1, H - 1)
    base, extra = divmod(rest, k)
    return [1] + [base + (1 if i < extra else 0) for i in range(k)]


def horizon_end(j: int, H: int, every: int, N: int) -> int:
    """The sample at which the prediction ends: the last multiple of ``every`` within j + H (where the
    design kept P), at least one sample ahead; j + H beyond the plan (P_S there).

    >>> horizon_end(3, 30, 10, 1000), horizon_end(9, 5, 10, 1000), horizon_end(990, 30, 10, 1000)
    (30, 10, 1020)
    """
    if j + H >= N:
        return j + H
    end = ((j + H) // every) * every
    return end if end > j else ((j // every) + 1) * every


@dataclass
class Prediction:
    """The condensed QP's pieces for one sample (exposed for the tests)."""

    qp: QP
    blocks: list[int]
    u_ff: Array  # (H, m) the feedforward along the horizon


def condensed_qp(gains: Gains, plan: FeedforwardPlan, c_m: Array, q0: float, q1: float, r0: float,
                 delta0: float, j: int, e0: Array, u_prev: Array | None, s: MPCSettings,
                 with_rates: bool = True) -> Prediction:
    """The MPC's QP at sample j from the augmented error e0 = [theta_hat - theta_ref,j ; e_I] (module docstring)."""
    n = e0.size - 1
    N = plan.n_steps
    end = horizon_end(j, s.horizon, gains.jacobian_every, N)
    H = end - j
    blocks = move_blocks(H, s.moves)
    m = plan.u_ff.shape[1]
    nz = m * len(blocks)
    # x_k = x_free_k + G_k z, split into the nodes (d) and the integral (I)
    d_free, I_free = e0[:n].copy(), float(e0[n])
    Gd, GI = np.zeros((n, nz)), np.zeros(nz)
    Hess, grad = np.zeros((nz, nz)), np.zeros(nz)
    c = np.asarray(c_m, float)
    u_ff = np.empty((H, m))
    t_s = plan.t_s
    k = 0
    for b, length in enumerate(blocks):
        cols = slice(b * m, (b + 1) * m)
        Hess[cols, cols] += r0 * length * np.eye(m)
        for _ in range(length):
            # stage cost of x_k (k = 0 is constant in z)
            if k > 0:
                act = slice(0, (b + 1) * m)
                cd = c @ Gd[:, act]
                gi = GI[act]
                Hess[act, act] += q0 * np.outer(cd, cd) + q1 * np.outer(gi, gi)
                grad[act] += (q0 * float(c @ d_free)) * cd + (q1 * I_free) * gi
            uf = plan.sample(j + k)[0]
            u_ff[k] = uf
            Phi, Gam = gains.linearisation(j + k)
            delta = anti_windup_delta(uf, delta0)
            # the integrator row of Phi~ (eq. 24) reads the nodes before the step
            act = slice(0, (b + 1) * m)  # later moves have not acted yet: their columns are 0
            I_free += delta * t_s * float(c @ d_free)
            GI[act] += delta * t_s * (c @ Gd[:, act])
            d_free = Phi @ d_free
            Gd[:, act] = Phi @ Gd[:, act]
            Gd[:, cols] += Gam
            k += 1
    PT = gains.cost_to_go(end)
    G_full = np.vstack([Gd, GI[None, :]])
    x_free = np.append(d_free, I_free)
    Hess += G_full.T @ PT @ G_full
    grad += G_full.T @ (PT @ x_free)
    # bounds per move: u in [0, 1] at every sample it is held
    lbx, ubx = np.empty(nz), np.empty(nz)
    starts = np.cumsum([0, *blocks[:-1]])
    for b, (k0, length) in enumerate(zip(starts, blocks, strict=True)):
        seg = u_ff[k0:k0 + length]
        lbx[b * m:(b + 1) * m] = np.max(-seg, axis=0)
        ubx[b * m:(b + 1) * m] = np.min(1.0 - seg, axis=0)
    if u_prev is not None:  # the first move's rate, as bounds (always feasible: u_prev is in [0, 1])
        lbx[:m] = np.maximum(lbx[:m], u_prev - s.rate - u_ff[0])
        ubx[:m] = np.minimum(ubx[:m], u_prev + s.rate - u_ff[0])
    rows = []
    lba, uba = [], []
    if with_rates:
        for b in range(1, len(blocks)):
            jump = u_ff[starts[b]] - u_ff[starts[b] - 1]
            R = np.zeros((m, nz))
            R[:, b * m:(b + 1) * m] = np.eye(m)
            R[:, (b - 1) * m:b * m] = -np.eye(m)
            rows.append(R)
            lba.append(-s.rate - jump)
            uba.append(s.rate - jump)
    A = np.vstack(rows) if rows else np.zeros((0, nz))
    qp = QP(H=0.5 * (Hess + Hess.T), g=grad, A=A, lba=np.concatenate(lba) if lba else np.zeros(0),
            uba=np.concatenate(uba) if uba else np.zeros(0), lbx=lbx, ubx=np.maximum(ubx, lbx))
    return Prediction(qp, blocks, u_ff)


@dataclass
class MPCController(Controller):
    """:class:`twin.control.lqg.Controller` with the MPC as its feedback (module docstring)."""

    settings: MPCSettings | None = None
    solver: QPSolver | None = None
    u_prev: Array | None = None
    fallbacks: int = 0
    #: wall time of each sample's MPC (ms)
    step_ms: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.settings is None:
            self.settings = mpc_settings(self.cfg)
        if self.solver is None:
            self.solver = make_solver(self.settings.solver)

    def control(self, j: int, theta_hat: ArrayLike) -> tuple[Array, Array, Array]:
        t0 = time.perf_counter()
        assert self.settings is not None and self.solver is not None
        th = np.asarray(theta_hat, float)
        u_ff, theta_ref, T_ref = self.plan.sample(j)
        n = th.size
        e = np.empty(n + 1)
        e[:n] = th - theta_ref
        e[n] = self.state.e_I
        c_m = np.asarray(self.model.c_m, float)
        w = self.cfg.lqg
        Kj = self.gains.at(j)
        du = None
        for with_rates in (True, False):
            pred = condensed_qp(self.gains, self.plan, c_m, w.q0, w.q1, w.r0, w.delta0, j, e, self.u_prev,
                                self.settings, with_rates)
            res = self.solver.solve(pred.qp)
            if res.ok:
                du = res.z[: u_ff.size]
                break
        if du is None:  # the LQG's input for this sample
            self.fallbacks += 1
            if self.fallbacks == 1 or self.fallbacks % 100 == 0:
                log.warning("MPC: no QP solution at sample %d (%d so far); the LQG's input is used", j,
                            self.fallbacks)
            du = Kj @ e
        u_raw = u_ff + du
        u = np.minimum(np.maximum(u_raw, 0.0), 1.0)
        mean_err = float(c_m @ th) - T_ref
        delta = integrator_delta(u, u_raw, Kj[:, n], mean_err, w.delta0)
        self.state = IntegratorState(self.state.e_I + delta * self.plan.t_s * mean_err, frozen=delta == 0.0)
        self.last = ControlOutput(u, u_ff.copy(), du, mean_err, delta)
        self.u_prev = u
        self.step_ms.append(1000.0 * (time.perf_counter() - t0))
        return u, u_ff.copy(), du

    def with_plan(self, plan: FeedforwardPlan, gains: Gains, model: DiscreteDynamics | None = None) -> MPCController:
        return MPCController(model or self.model, plan, gains, self.cfg,
                             IntegratorState(self.state.e_I, self.state.frozen), None, self.settings, self.solver,
                             self.u_prev, self.fallbacks, self.step_ms)


def mpc_settings(cfg: FurnaceConfig) -> MPCSettings:
    """The MPC's settings from ``[control]`` of a furnace configuration."""
    ctl = cfg.control
    t_s = float(cfg.sampling.t_s)
    return MPCSettings(horizon=max(1, int(round(ctl.mpc_horizon / t_s))), moves=int(ctl.mpc_moves),
                       rate=float(ctl.mpc_rate) * t_s, solver=str(ctl.mpc_solver))


def make_controller(feedback: str, model: DiscreteDynamics, plan: FeedforwardPlan, gains: Gains,
                    cfg: FurnaceConfig) -> Controller:
    """The LQG's :class:`Controller` or the :class:`MPCController`, by name."""
    if feedback == "mpc":
        return MPCController(model, plan, gains, cfg)
    if feedback == "lqg":
        return Controller(model, plan, gains, cfg)
    raise ValueError(f"feedback must be 'lqg' or 'mpc', got {feedback!r}")
