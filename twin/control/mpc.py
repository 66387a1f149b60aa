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
from functools import lru_cache

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
    #: weight of the fillet's variance theta^T W theta (eq. 21) at the horizon's end (0: the LQG's cost alone)
    homogeneity: float = 0.0


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


def anti_windup_deltas(u_ff: Array, delta0: float) -> Array:
    """delta of Remark 5 (:func:`twin.control.lqg.anti_windup_delta`) of each row of u_ff (N, m)."""
    return np.array([anti_windup_delta(u, delta0) for u in u_ff], dtype=float).reshape(len(u_ff))


@dataclass
class Prediction:
    """The condensed QP's pieces for one sample (exposed for the tests)."""

    qp: QP
    blocks: list[int]
    u_ff: Array  # (H, m) the feedforward along the horizon


@dataclass(frozen=True)
class SegmentPowers:
    """Powers of one held linearisation (Phi, Gamma), up to ``every`` steps: Phi^p, c^T Phi^p and Phi^p Gamma.

    The design holds Phi_j, Gamma_j over ``jacobian_every`` samples (:func:`twin.control.lqg.lqg_gains`), so the
    prediction crosses a held stretch of L steps with one product Phi^L G instead of L products (the MPC's cost
    per sample drops about L-fold), and reads the fillet mean inside it from the rows c^T Phi^l."""

    Phi_pow: Array  # (E + 1, n, n): Phi^0 .. Phi^E
    rows: Array  # (E + 1, n): c^T Phi^p
    gam_pow: Array  # (E, n, m): Phi^p Gamma, p = 0 .. E - 1
    c_gam: Array  # (E, m): c^T Phi^p Gamma
    gam_rev: Array  # (E, n, m): gam_pow backwards, Phi^(E-1-p) Gamma (a view)
    c_gam0: Array  # (E + 1, m): c_gam, then a row of zeros at index E (a step's input not yet reached: no term)

    @classmethod
    def of(cls, Phi: Array, Gam: Array, c: Array, E: int) -> SegmentPowers:
        n = Phi.shape[0]
        P = np.empty((E + 1, n, n))
        P[0] = np.eye(n)
        for p in range(1, E + 1):
            P[p] = Phi @ P[p - 1]
        rows = np.einsum("i,pij->pj", c, P)
        gam = P[:E] @ Gam
        c_gam = np.einsum("i,pim->pm", c, gam)
        return cls(P, rows, gam, c_gam, gam[::-1], np.concatenate([c_gam, np.zeros((1, c_gam.shape[1]))]))


def _add_in_order(into: Array, terms: Array) -> None:
    """into += terms[0]; into += terms[1]; ... at one numpy call: numpy reduces over the first axis of a stack
    slice by slice, in order (pairwise summation is only used along the contiguous last axis), so the sums are
    the loop's to the bit; a test holds condensed_qp to the loop it replaced."""
    if len(terms) == 1:
        into += terms[0]
    else:
        np.add.reduce(np.concatenate([into[None], terms]), axis=0, out=into)


@lru_cache(maxsize=1024)
def _toeplitz(steps: int, rows: int, zero: int) -> NDArray[np.intp]:
    """(steps, rows) indices into c^T Phi^p Gamma for the rows after a move's first step a: the input of step
    a + t reaches row a + 1 + r through c^T Phi^(r - t) Gamma when r >= t, else not at all (``zero``, the index
    of a row of zeros; adding an exact zero leaves a sum as it was)."""
    r = np.arange(rows)[None, :] - np.arange(steps)[:, None]
    out = np.where(r >= 0, r, zero)
    out.flags.writeable = False
    return out


@lru_cache(maxsize=4096)
def _moves_in(blocks: tuple[int, ...], k0: int, L: int) -> tuple[tuple[int, int, int], ...]:
    """(move b, first step a, end e) of each move held in the steps k0 .. k0 + L - 1, a and e counted from k0.

    >>> _moves_in((1, 8, 7), 0, 10), _moves_in((1, 8, 7), 10, 6)
    (((0, 0, 1), (1, 1, 9), (2, 9, 10)), ((2, 0, 6),))
    """
    out, s0 = [], 0
    for b, length in enumerate(blocks):
        a, e = max(s0, k0), min(s0 + length, k0 + L)
        if a < e:
            out.append((b, a - k0, e - k0))
        s0 += length
    return tuple(out)


def _segments(j: int, end: int, N: int, every: int) -> list[tuple[int, int, int]]:
    """(first step k0, length L, linearisation key) of the held stretches of the horizon j .. end - 1 (key: the
    held index s // every inside the plan, -1 beyond it, cut every ``every`` steps)."""
    out = []
    k = 0
    while j + k < end:
        s = j + k
        if s < N:
            key = s // every
            stop = min((key + 1) * every, N, end)
        else:
            key = -1
            stop = min(s + every, end)
        out.append((k, stop - s, key))
        k = stop - j
    return out


@lru_cache(maxsize=256)
def _structure(blocks: tuple[int, ...], m: int, r0: float, n_rates: int) -> tuple[Array, Array, NDArray[np.intp]]:
    """What the QP's shape alone fixes (made once per shape, not per sample; read-only): the input weight's part of
    the Hessian (r0 |Delta u|^2 over each move's samples), the rate rows and the first step of each move (the moves
    a held stretch's steps belong to: :func:`_moves_in`)."""
    nz = m * len(blocks)
    Hess = np.zeros((nz, nz))
    eye_m = np.eye(m)
    for b, length in enumerate(blocks):
        Hess[b * m:(b + 1) * m, b * m:(b + 1) * m] += r0 * length * eye_m
    A = np.zeros((n_rates * m, nz))
    for b in range(1, n_rates + 1):  # u of move b minus u of move b - 1, within the rate bound
        A[(b - 1) * m:b * m, b * m:(b + 1) * m] = eye_m
        A[(b - 1) * m:b * m, (b - 1) * m:b * m] = -eye_m
    starts = np.cumsum([0, *blocks[:-1]])
    for a in (Hess, A, starts):
        a.flags.writeable = False
    return Hess, A, starts


def condensed_qp(gains: Gains, plan: FeedforwardPlan, c_m: Array, q0: float, q1: float, r0: float,
                 delta0: float, j: int, e0: Array, u_prev: Array | None, s: MPCSettings,
                 with_rates: bool = True, cache: dict[int, SegmentPowers] | None = None,
                 plan_deltas: Array | None = None, W: Array | None = None) -> Prediction:
    """The MPC's QP at sample j from the augmented error e0 = [theta_hat - theta_ref,j ; e_I] (module docstring).

    ``cache``: :class:`SegmentPowers` of the held linearisations by key, kept between samples of one plan;
    ``plan_deltas``: :func:`anti_windup_deltas` of the plan's u_ff (made once per plan instead of per sample)."""
    n = e0.size - 1
    N = plan.n_steps
    every = gains.jacobian_every
    end = horizon_end(j, s.horizon, every, N)
    H = end - j
    blocks = move_blocks(H, s.moves)
    m = plan.u_ff.shape[1]
    nz = m * len(blocks)
    n_rates = len(blocks) - 1 if with_rates else 0
    move_key = tuple(blocks)
    Hess0, A0, starts = _structure(move_key, m, float(r0), n_rates)
    store = {} if cache is None else cache
    # x_k = x_free_k + G_k z, split into the nodes (d) and the integral (I)
    d_free = e0[:n].copy()
    Gd = np.zeros((n, nz))
    Hess = Hess0.copy()
    c = np.asarray(c_m, float)
    t_s = plan.t_s
    rows_ff = np.minimum(np.arange(j, end), N - 1)  # plan.sample(j + k): the last input held beyond the plan
    u_ff = plan.u_ff[rows_ff]
    deltas = plan_deltas[rows_ff] if plan_deltas is not None else anti_windup_deltas(u_ff, delta0)
    Y, yf = np.zeros((H, nz)), np.empty(H)  # the fillet mean's response c^T d_k before each step k
    # Only the moves already reached act on d_k: the columns of Gd from the next move on are exact zeros.  The
    # products take the columns reached (``live``) alone; a product with zero columns is exactly zero, so the QP
    # is the same to the bit at a third of the products (issue 21).
    live = 0
    for k0, L, key in _segments(j, end, N, every):
        powers = store.get(key)
        if powers is None:
            Phi, Gam = gains.linearisation(j + k0)
            powers = store[key] = SegmentPowers.of(np.asarray(Phi, float), np.asarray(Gam, float), c, every)
        Yseg = Y[k0:k0 + L]  # (L, nz), zeros
        if live:
            Yseg[:, :live] = powers.rows[:L] @ Gd[:, :live]
        yf[k0:k0 + L] = powers.rows[:L] @ d_free
        runs = _moves_in(move_key, k0, L)
        for b, a, e in runs:  # the input of steps a .. e - 1 reaches the mean of the later steps
            if a < L - 1:
                _add_in_order(Yseg[a + 1:, b * m:(b + 1) * m],
                              powers.c_gam0[_toeplitz(min(e, L - 1) - a, L - 1 - a, every)])
        if live:
            Gd[:, :live] = powers.Phi_pow[L] @ Gd[:, :live]
        d_free = powers.Phi_pow[L] @ d_free
        for b, a, e in runs:  # step k0 + i adds Phi^(L-1-i) Gamma: i = a .. e - 1 reads gam_rev[E-L+a : E-L+e]
            _add_in_order(Gd[:, b * m:(b + 1) * m], powers.gam_rev[every - L + a:every - L + e])
        live = (runs[-1][0] + 1) * m  # up to the move of the stretch's last step
    # the integral (eq. 22, the integrator row of Phi~ in eq. 24) before each step k = 0 .. H
    w_int = (deltas * t_s)[:, None]
    GI = np.vstack([np.zeros((1, nz)), np.cumsum(w_int * Y, axis=0)])  # (H + 1, nz)
    I_all = float(e0[n]) + np.concatenate([[0.0], np.cumsum(w_int[:, 0] * yf)])
    # stage costs of x_1 .. x_H-1 (x_0 does not depend on z)
    Ys, GIs = Y[1:], GI[1:H]
    Hess += q0 * (Ys.T @ Ys) + q1 * (GIs.T @ GIs)
    grad = q0 * (Ys.T @ yf[1:]) + q1 * (GIs.T @ I_all[1:H])
    GI, I_free = GI[H], float(I_all[H])
    PT = gains.cost_to_go(end)
    G_full = np.vstack([Gd, GI[None, :]])
    x_free = np.append(d_free, I_free)
    Hess += G_full.T @ PT @ G_full
    grad += G_full.T @ (PT @ x_free)
    # (q_W / 2) theta_H^T W theta_H, theta_H = theta_ref,H + d_H, while the reference holds still over the horizon
    if W is not None and s.homogeneity > 0.0 and plan.T_ref[min(end, N)] == plan.T_ref[min(j, N)]:
        WGd = W @ Gd
        Hess += s.homogeneity * (Gd.T @ WGd)
        grad += s.homogeneity * (WGd.T @ (d_free + plan.theta_ref[min(end, N)]))
    # bounds per move: u in [0, 1] at every sample it is held
    lbx = np.maximum.reduceat(-u_ff, starts, axis=0).ravel()  # per move: max(-u_ff), min(1 - u_ff) of its samples
    ubx = np.minimum.reduceat(1.0 - u_ff, starts, axis=0).ravel()
    if u_prev is not None:  # the first move's rate, as bounds (always feasible: u_prev is in [0, 1])
        lbx[:m] = np.maximum(lbx[:m], u_prev - s.rate - u_ff[0])
        ubx[:m] = np.minimum(ubx[:m], u_prev + s.rate - u_ff[0])
    A = A0.copy()
    jump = (u_ff[starts[1:]] - u_ff[starts[1:] - 1])[:n_rates].ravel()
    qp = QP(H=0.5 * (Hess + Hess.T), g=grad, A=A, lba=-s.rate - jump, uba=s.rate - jump, lbx=lbx,
            ubx=np.maximum(ubx, lbx))
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
    #: the held linearisations' powers of this plan (condensed_qp's cache)
    powers: dict[int, SegmentPowers] = field(default_factory=dict)
    #: delta of Remark 5 at every sample of this plan (condensed_qp's ``plan_deltas``), made at the first sample
    deltas: Array | None = None

    def __post_init__(self) -> None:
        if self.settings is None:
            self.settings = mpc_settings(self.cfg)
        if self.solver is None:
            self.solver = make_solver(self.settings.solver)
        #: W of eq. (21) when the settings weigh the fillet's variance (made once: fe.W builds it on every call)
        self.variance = np.asarray(self.model.W, float) if self.settings.homogeneity > 0.0 else None

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
        for key in [k for k in self.powers if 0 <= k < j // self.gains.jacobian_every]:
            del self.powers[key]  # stretches behind: ~1 MB each
        if self.deltas is None:
            self.deltas = anti_windup_deltas(self.plan.u_ff, w.delta0)
        du = None
        for with_rates in (True, False):
            pred = condensed_qp(self.gains, self.plan, c_m, w.q0, w.q1, w.r0, w.delta0, j, e, self.u_prev,
                                self.settings, with_rates, self.powers, self.deltas, self.variance)
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
                       rate=float(ctl.mpc_rate) * t_s, solver=str(ctl.mpc_solver),
                       homogeneity=float(ctl.mpc_homogeneity))


def make_controller(feedback: str, model: DiscreteDynamics, plan: FeedforwardPlan, gains: Gains,
                    cfg: FurnaceConfig) -> Controller:
    """The LQG's :class:`Controller` or the :class:`MPCController`, by name."""
    if feedback == "mpc":
        return MPCController(model, plan, gains, cfg)
    if feedback == "lqg":
        return Controller(model, plan, gains, cfg)
    raise ValueError(f"feedback must be 'lqg' or 'mpc', got {feedback!r}")
