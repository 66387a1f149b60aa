"""Time-varying LQG tracking feedback with integral action (paper section 4.2, eqs. 22-29).

The feedback acts on the augmented error e_j = [theta_hat_j - theta_ref,j ; e_I,j]
(eq. 24) with the gains K_j of the finite-horizon LQ problem (27) along the plan:
the Riccati recursion (26), (29) runs backwards from P_N = P_S, the solution of the
discrete algebraic Riccati equation (DARE) at the last point of the plan.  Beyond
the plan's horizon the terminal gain is used.

The DARE is solved by the structure-preserving doubling algorithm (Chu et al.,
SIAM J. Matrix Anal. Appl. 26, 2004), so the tests can use scipy's QZ-based
``solve_discrete_are`` and python-control's ``dlqr`` as independent oracles.

Example
-------
>>> import numpy as np
>>> A, B = np.array([[0.9]]), np.array([[1.0]])
>>> P = dare(A, B, np.array([[1.0]]), 1.0)
>>> round(float(P[0, 0]), 6)  # P = 1 + 0.81 P / (1 + P)  ->  P = (0.81 + sqrt(0.81^2 + 4)) / 2
1.4839
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.control.plan import FeedforwardPlan
from twin.model.dynamics import DiscreteDynamics

log = logging.getLogger(__name__)

Array = NDArray[np.float64]


class RiccatiError(ArithmeticError):
    """The DARE has no stabilizing solution (doubling did not converge)."""


def weight_matrix(c_m: ArrayLike, q0: float, q1: float) -> Array:
    """Q of eq. (28): ``[[q0 c_m c_m^T, 0], [0, q1]]`` for the augmented error (n + 1,)."""
    c = np.asarray(c_m, float)
    n = c.size
    Q = np.zeros((n + 1, n + 1))
    Q[:n, :n] = q0 * np.outer(c, c)
    Q[n, n] = q1
    return Q


def augmented_system(Phi: ArrayLike, Gamma: ArrayLike, c_m: ArrayLike, t_s: float,
                     delta: float) -> tuple[Array, Array]:
    """Phi~_j and Gamma~_j of the augmented error dynamics, eq. (24).

    Parameters
    ----------
    Phi : (n, n), Gamma : (n, m)
        Linearization (23) of the discrete model along the plan.
    c_m : (n,)
        Fillet-mean vector of eq. (19).
    t_s : float
        Sampling time (s).
    delta : float
        Anti-windup factor delta(u_j) in {0, 1} (Remark 5).
    """
    P = np.asarray(Phi, float)
    G = np.asarray(Gamma, float)
    n, m = G.shape
    Pt = np.zeros((n + 1, n + 1))
    Pt[:n, :n] = P
    Pt[n, :n] = delta * t_s * np.asarray(c_m, float)
    Pt[n, n] = 1.0
    Gt = np.zeros((n + 1, m))
    Gt[:n] = G
    return Pt, Gt


def riccati_step(P_next: Array, Phi_t: Array, Gamma_t: Array, Q: Array, r0: float) -> tuple[Array, Array]:
    """One backward step of the Riccati recursion: (P_j, K_j) from P_{j+1}, eqs. (26), (29).

    ``K_j = -(r0 I + G^T P G)^-1 G^T P F`` and ``P_j = Q + F^T P F + (G^T P F)^T K_j``
    with F = Phi~_j, G = Gamma~_j, P = P_{j+1}.
    """
    PF = P_next @ Phi_t
    GtPF = Gamma_t.T @ PF
    S = r0 * np.eye(Gamma_t.shape[1]) + Gamma_t.T @ P_next @ Gamma_t
    K = np.asarray(-np.linalg.solve(S, GtPF), dtype=np.float64)
    P = Q + Phi_t.T @ PF + GtPF.T @ K
    return 0.5 * (P + P.T), K


def lq_gain(P: Array, Phi_t: Array, Gamma_t: Array, r0: float) -> Array:
    """K of eq. (26) for a given cost-to-go matrix P (m, n + 1)."""
    S = r0 * np.eye(Gamma_t.shape[1]) + Gamma_t.T @ P @ Gamma_t
    K = np.asarray(-np.linalg.solve(S, Gamma_t.T @ P @ Phi_t), dtype=np.float64)
    return K


def dare(A: ArrayLike, B: ArrayLike, Q: ArrayLike, r0: float, *, tol: float = 1e-13,
         max_iter: int = 100) -> Array:
    """Stabilizing solution P_S of ``P = Q + A^T P A - A^T P B (r0 I + B^T P B)^-1 B^T P A``.

    The terminal condition of the recursion (29) (paper, end of section 4.2).
    Structure-preserving doubling: with G = B B^T / r0, iterate
    ``W = I + G_k H_k``, ``A_k+1 = A_k W^-1 A_k``, ``G_k+1 = G_k + A_k W^-1 G_k A_k^T``,
    ``H_k+1 = H_k + A_k^T H_k W^-1 A_k`` from H_0 = Q; H_k -> P_S quadratically.

    Raises
    ------
    RiccatiError
        If the iteration does not converge (no stabilizing solution).
    """
    Ak = np.asarray(A, float).copy()
    Bm = np.asarray(B, float)
    Hk = np.asarray(Q, float).copy()
    Gk = Bm @ Bm.T / r0
    eye = np.eye(Ak.shape[0])
    for _ in range(max_iter):
        W = eye + Gk @ Hk
        WiA = np.linalg.solve(W, Ak)
        WiG = np.linalg.solve(W, Gk)
        H_new = Hk + Ak.T @ Hk @ WiA
        G_new = Gk + Ak @ WiG @ Ak.T
        Ak = Ak @ WiA
        H_new = 0.5 * (H_new + H_new.T)
        G_new = 0.5 * (G_new + G_new.T)
        change = float(np.max(np.abs(H_new - Hk)))
        Hk, Gk = H_new, G_new
        if not np.all(np.isfinite(Hk)):
            break
        if change <= tol * max(1.0, float(np.max(np.abs(Hk)))):
            return Hk
    raise RiccatiError("DARE doubling did not converge: (A, B) not stabilizable or (Q, A) not detectable")


def anti_windup_delta(u: ArrayLike, delta0: float) -> float:
    """delta(u) of Remark 5: 0 if 1^T u > delta0 (total power high), else 1."""
    return 0.0 if float(np.sum(u)) > delta0 else 1.0


@dataclass(frozen=True)
class Gains:
    """Time-varying feedback gains of eq. (26).

    Attributes
    ----------
    K : array (N, m, n + 1)
        K_j for the samples of the plan; Delta u_j = K_j e_j (eq. 25).
    K_terminal : array (m, n + 1)
        Gain of the DARE at the plan's last point, used for j >= N.
    P_terminal : array (n + 1, n + 1)
        P_S, the DARE solution.
    jacobian_every : int
        Phi_j, Gamma_j were evaluated every this many samples and held in between.
    design_s : float
        Wall time of the design (s).
    """

    K: Array
    K_terminal: Array
    P_terminal: Array
    jacobian_every: int = 1
    design_s: float = 0.0
    Phi: Array | None = None
    Gamma: Array | None = None
    P: Array | None = None
    Phi_terminal: Array | None = None
    Gamma_terminal: Array | None = None

    def at(self, j: int) -> Array:
        """K_j, or the terminal gain beyond the horizon."""
        return self.K[j] if 0 <= j < self.K.shape[0] else self.K_terminal

    def linearisation(self, j: int) -> tuple[Array, Array]:
        """(Phi_j, Gamma_j) of eq. (23) as the design used them (held over ``jacobian_every`` samples; the
        terminal ones beyond the plan)."""
        if self.Phi is None or self.Gamma is None or self.Phi_terminal is None or self.Gamma_terminal is None:
            raise ValueError("these gains were made without their linearisation")
        if 0 <= j < self.K.shape[0]:
            i = j // self.jacobian_every
            return self.Phi[i], self.Gamma[i]
        return self.Phi_terminal, self.Gamma_terminal

    def cost_to_go(self, j: int) -> Array:
        """P_j of the recursion (29) at a multiple j of ``jacobian_every`` (P_S at and beyond the plan's end)."""
        if self.P is None:
            raise ValueError("these gains were made without their cost-to-go")
        if j >= self.K.shape[0]:
            return self.P_terminal
        if j % self.jacobian_every:
            raise ValueError(f"P_j is kept at multiples of {self.jacobian_every} samples only, not at {j}")
        return self.P[j // self.jacobian_every]


#: samples of the Riccati recursion between two budget checks (a few ms)
CHECK_EVERY = 50


def lqg_gains(model: DiscreteDynamics, plan: FeedforwardPlan, cfg: FurnaceConfig, *,
              jacobian_every: int = 1, check: Callable[[], None] | None = None) -> Gains:
    """Time-varying LQ gains along a plan, eqs. (23)-(29).

    Parameters
    ----------
    model : DiscreteModel
        ``jac_theta``, ``jac_u`` (eq. 23), ``c_m``, ``t_s``.
    plan : FeedforwardPlan
        theta_ref,j and u_ff,j to linearize about.
    cfg : FurnaceConfig
        Weights ``cfg.lqg.q0, q1, r0`` (eqs. 27-28) and ``delta0`` (Remark 5).
    jacobian_every : int
        Evaluate Phi_j, Gamma_j only every this many samples and hold them in between
        (a Jacobian of the full model costs milliseconds; 1 = every sample).
    check : callable, optional
        Called every :data:`CHECK_EVERY` samples; it raises to end the design (a cancelled or spent
        :class:`twin.control.budget.PlanBudget`).

    Notes
    -----
    delta(u_j) in Phi~_j (24) is evaluated on the feedforward u_ff,j (the applied input
    is not known at design time).  The terminal DARE uses delta = 1: in steady state
    the integrator must act, and with delta = 0 its mode would be uncontrollable.
    BLAS runs single-threaded here: for ~106 x 106 products threads only contend on
    the shared cores (the DARE took 1.9 s multi-threaded vs 0.07 s on one thread).
    """
    return _lqg_gains(model, plan, cfg, jacobian_every, check or (lambda: None))


def _lqg_gains(model: DiscreteDynamics, plan: FeedforwardPlan, cfg: FurnaceConfig,
               jacobian_every: int, check: Callable[[], None]) -> Gains:
    t_start = time.perf_counter()
    w = cfg.lqg
    c_m = np.asarray(model.c_m, float)
    t_s = plan.t_s
    N = plan.n_steps
    n, m = model.n, model.m
    Q = weight_matrix(c_m, w.q0, w.q1)
    every = max(1, int(jacobian_every))

    u_last = plan.u_ff[-1]
    Phi_N = np.asarray(model.jac_theta(plan.theta_ref[N], u_last), float)
    Gam_N = np.asarray(model.jac_u(plan.theta_ref[N], u_last), float)
    Pt_N, Gt_N = augmented_system(Phi_N, Gam_N, c_m, t_s, 1.0)
    P = dare(Pt_N, Gt_N, Q, w.r0)
    K_term = lq_gain(P, Pt_N, Gt_N, w.r0)
    P_S = P

    K = np.empty((N, m, n + 1))
    n_held = (N - 1) // every + 1
    Phis, Gams, Ps = np.empty((n_held, n, n)), np.empty((n_held, n, m)), np.empty((n_held, n + 1, n + 1))
    key: tuple[int, float] | None = None
    Pt = Gt = np.empty(0)
    for j in range(N - 1, -1, -1):
        if j % CHECK_EVERY == 0:
            check()
        jj = (j // every) * every
        delta = anti_windup_delta(plan.u_ff[j], w.delta0)
        if key is None or key[0] != jj:
            Phi = np.asarray(model.jac_theta(plan.theta_ref[jj], plan.u_ff[jj]), float)
            Gam = np.asarray(model.jac_u(plan.theta_ref[jj], plan.u_ff[jj]), float)
            Phis[jj // every], Gams[jj // every] = Phi, Gam
            Pt, Gt = augmented_system(Phi, Gam, c_m, t_s, delta)
        elif key[1] != delta:
            Pt = Pt.copy()
            Pt[n, :n] = delta * t_s * c_m
        key = (jj, delta)
        P, K[j] = riccati_step(P, Pt, Gt, Q, w.r0)
        if j == jj:
            Ps[j // every] = P  # the cost-to-go P_j: the MPC's terminal cost (twin.control.mpc)
    elapsed = time.perf_counter() - t_start
    log.info("LQG gains for %d samples (Jacobians every %d) in %.2f s", N, every, elapsed)
    return Gains(K, K_term, P_S, every, elapsed, Phis, Gams, Ps, Phi_N, Gam_N)


@dataclass
class IntegratorState:
    """e_I,j of eq. (22) in K s, and whether it was frozen at the last step."""

    e_I: float = 0.0
    frozen: bool = False


@dataclass(frozen=True)
class ControlOutput:
    """One controller step: applied u, its feedforward and feedback parts, and the errors."""

    u: Array
    u_ff: Array
    du: Array
    mean_error: float
    delta: float


def integrator_delta(u_applied: Array, u_unclipped: Array, k_int: Array, mean_error: float,
                     delta0: float) -> float:
    """Anti-windup factor delta(u_j) in {0, 1} for eq. (22).

    The integrator is frozen (delta = 0)

    * when the total power 1^T u_j exceeds ``delta0`` (Remark 5 of the paper), or
    * when no group can follow the integrator: every group is clipped at the bound
      that the integrator increment ``k_int t_s e_j`` pushes it against (at u = 1
      while the increment raises it, at u = 0 while it lowers it).

    Freezing as soon as *any* group is clipped was tried and rejected: on the default
    furnace the plan's strongest group runs at u = 1 in steady state when the plant's
    lamps are 15 % weaker than the model's, and the integrator then stayed frozen with
    a 10 K mean offset although the other groups had power to spare.
    """
    if float(u_applied.sum()) > delta0:
        return 0.0
    if mean_error == 0.0:
        return 1.0  # nothing to integrate
    push = k_int * mean_error  # sign of the change of du from e_I += t_s e (t_s > 0)
    movable = ((push > 0) & (u_unclipped < 1.0)) | ((push < 0) & (u_unclipped > 0.0))
    return 1.0 if movable.any() else 0.0


def feedback_control(gains: Gains, plan: FeedforwardPlan, c_m: Array, delta0: float, j: int,
                     theta_hat: ArrayLike, state: IntegratorState) -> tuple[ControlOutput, IntegratorState]:
    """u_j = sat(u_ff,j + K_j e_j) and the integrator update (eqs. 17, 22, 25), pure.

    Returns the step's output and the new integrator state (``state`` is not changed).
    """
    th = np.asarray(theta_hat, float)
    u_ff, theta_ref, T_ref = plan.sample(j)
    n = th.size
    e = np.empty(n + 1)
    e[:n] = th - theta_ref
    e[n] = state.e_I
    Kj = gains.at(j)
    du = Kj @ e
    u_raw = u_ff + du
    u = np.minimum(np.maximum(u_raw, 0.0), 1.0)  # sat, eq. (17) (np.clip costs twice as much)
    mean_err = float(c_m @ th) - T_ref  # eq. (19) with the requested T_ref,j
    delta = integrator_delta(u, u_raw, Kj[:, n], mean_err, delta0)
    new = IntegratorState(state.e_I + delta * plan.t_s * mean_err, frozen=delta == 0.0)
    return ControlOutput(u, u_ff.copy(), du, mean_err, delta), new


def carried_integrator(old_plan: FeedforwardPlan, old_gains: Gains, new_plan: FeedforwardPlan, new_gains: Gains,
                       t: float, theta_hat: ArrayLike, state: IntegratorState) -> IntegratorState:
    """e_I on a new plan of the same goal (a calibration's re-plan): the input does not jump at the switch.

    The integrator's part of the input is k e_I (k: the integrator's column of K_j, eq. 25).  At the switch the
    old controller would apply u_old = u_ff,old + K_old (theta_hat - theta_ref,old; e_I) (unclipped), the new one
    u_ff,new + K_new,theta (theta_hat - theta_ref,new) + k_new e_I'; e_I' solves
    min sum_g (k_new,g e_I' - (u_old,g - u_ff,new,g - K_new,theta,g (theta_hat - theta_ref,new)))^2 over the
    groups the old input did not clip (a clipped group gives nothing to match); with every group clipped e_I is
    kept.  A calibration that found the lamps weaker raises the feedforward, and e_I falls by what it no longer
    has to make up; it keeps what else it was making up for, which a reset would lose.  Matched at the switch,
    not over the rest of the plans: the re-plan starts from the held field at the reference's mean
    (:meth:`twin.runs.live_changes.LiveChanges.request`), so the new plan's first samples already hold; a plan
    from the estimate itself would correct the mean's error in its first seconds (its first 3 s at zero power
    on the small furnace 16 s after a 60 s heat-up, 18 K above the reference) while the integrator still made
    up for it (``theta_hat`` is the estimate at the switch, for the old input)."""
    th = np.asarray(theta_hat, float)
    n = th.size
    j_old, j_new = max(old_plan.index_at(t), 0), max(new_plan.index_at(t), 0)
    u_ff, theta_ref, _ = old_plan.sample(j_old)
    K_old, k_new = old_gains.at(j_old), new_gains.at(j_new)[:, n]
    u_old = u_ff + K_old @ np.append(th - theta_ref, state.e_I)  # unclipped
    free = (u_old > 0.0) & (u_old < 1.0)
    kk = float(k_new[free] @ k_new[free])
    if not free.any() or kk <= 0.0:
        return IntegratorState(state.e_I, state.frozen)
    u_ff_new, theta_ref_new, _ = new_plan.sample(j_new)
    K_new = new_gains.at(j_new)
    target = u_old - (u_ff_new + K_new[:, :n] @ (th - theta_ref_new))  # what the new input lacks at the switch
    return IntegratorState(float(k_new[free] @ target[free]) / kk, state.frozen)


@dataclass
class Controller:
    """The two-degree-of-freedom controller u = sat(u_ff + K_j e_j) (eqs. 17, 25).

    Holds the plan, the gains and the integrator state (explicitly, in ``state``).

    Example (the loop): ``u, u_ff, du = controller.control(j, theta_hat)``.
    """

    model: DiscreteDynamics
    plan: FeedforwardPlan
    gains: Gains
    cfg: FurnaceConfig
    state: IntegratorState = field(default_factory=IntegratorState)
    last: ControlOutput | None = None

    def control(self, j: int, theta_hat: ArrayLike) -> tuple[Array, Array, Array]:
        """Inputs for sample j of the plan from the estimate theta_hat (K).

        Returns (u, u_ff, du): applied group fractions clipped to [0, 1], feedforward
        part, and the unclipped feedback correction K_j e_j.  Updates e_I (eq. 22).
        """
        out, self.state = feedback_control(
            self.gains, self.plan, np.asarray(self.model.c_m, float), self.cfg.lqg.delta0, j,
            theta_hat, self.state,
        )
        self.last = out
        return out.u, out.u_ff, out.du

    def control_at(self, t: float, theta_hat: ArrayLike) -> tuple[Array, Array, Array]:
        """As :meth:`control` for run time ``t`` (s)."""
        return self.control(self.plan.index_at(t), theta_hat)

    def with_plan(self, plan: FeedforwardPlan, gains: Gains,
                  model: DiscreteDynamics | None = None) -> Controller:
        """A controller on a new plan (after a re-plan) that keeps the integrator state."""
        return Controller(model or self.model, plan, gains, self.cfg,
                          IntegratorState(self.state.e_I, self.state.frozen))
