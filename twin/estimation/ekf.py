"""Extended Kalman filter for the reduced FE temperature state (paper section 3.2, eqs. 12-16).

Predict (14), (15)::

    theta^-_{j+1} = F(theta_j, u_j),   P_{j+1} = Phi_j P^+_j Phi_j^T + Q,   Phi_j = dF/dtheta (16)

Update (13) with the TC readings y_j = C theta_j + v_j (12b)::

    L_j = P_j C^T (C P_j C^T + R)^{-1},   theta_j = theta^-_j + L_j (y_j - C theta^-_j),
    P^+_j = (I - L_j C) P_j (I - L_j C)^T + L_j R L_j^T        (Joseph form)

The Joseph form equals (I - L C) P of eq. (15) for the optimal gain and keeps P symmetric
positive definite in floating point.  Faulty TCs (NaN / inf reading or a normalised innovation
|nu_i| / sqrt(S_ii) above ``cfg.ekf.innovation_gate``) are left out of that update with a
logged warning.  If every working TC (at least two) fails the gate at once, the estimate is
taken to be wrong rather than all sensors: P is inflated until the closest reading sits at the gate
and all readings are used, so the filter recovers instead of gating itself off for ever.
Q = q0 (q1 sign(M) + 1 1^T)^2 and R = r0 I (section 3.2).

Example
-------
>>> import numpy as np
>>> s = EKFState(np.zeros(2), np.eye(2))
>>> s2, info = ekf_update(s, np.array([1.0]), np.array([[1.0, 0.0]]), np.eye(1), gate=np.inf)
>>> round(float(s2.theta[0]), 3), info.used.tolist()
(0.5, [True])
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg.lapack import dposv as _dposv

from twin.config import FurnaceConfig

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

class Dynamics(Protocol):
    """A discrete-time model theta_{j+1} = F(theta_j, u_j) with its Jacobian (e.g. DiscreteModel)."""

    def step(self, theta: ArrayLike, u: ArrayLike) -> Array: ...

    def jac_theta(self, theta: ArrayLike, u: ArrayLike) -> Array: ...


@dataclass(frozen=True)
class EKFState:
    """Estimate theta (n,) in K and its error covariance P (n, n) in K^2."""

    theta: Array
    P: Array


@dataclass(frozen=True)
class UpdateInfo:
    """What one measurement update did.

    innovation : (p,) y - C theta^- in K (NaN where the reading was NaN)
    normalized : (p,) |innovation| / sqrt(S_ii)
    used : (p,) bool, readings that entered the update
    reasons : (p,) "" if used, else "missing" or "gated"
    S : (p, p) innovation covariance C P^- C^T + R of all p readings (K^2), for fault tests
    gain : (n, p) Kalman gain L_j applied (zero columns for readings left out), for fault signatures
    """

    innovation: Array
    normalized: Array
    used: NDArray[np.bool_]
    reasons: tuple[str, ...] = field(default_factory=tuple)
    S: Array | None = None
    gain: Array | None = None


def process_noise(M: Array, q0: float, q1: float) -> Array:
    """Q = q0 (q1 sign(M) + 1 1^T)^2 (matrix square, section 3.2), symmetric PSD, K^2."""
    n = M.shape[0]
    S = q1 * np.sign(M) + np.ones((n, n))
    return q0 * (S @ S)


def propagate_covariance(Phi: NDArray[np.floating[Any]], P: Array, Q: Array) -> Array:
    """P^- = Phi P Phi^T + Q of eq. (15), symmetrised (a new float64 array).

    The product Phi P Phi^T is formed in Phi's precision: a float32 Phi (``ekf.covariance_precision
    = "single"``, see :class:`Estimator`) halves the cost of the two n x n x n products.
    """
    if Phi.dtype == np.float64:
        out = Phi @ P @ Phi.T
    else:
        out = (Phi @ P.astype(Phi.dtype) @ Phi.T).astype(np.float64)
    out += Q
    out += out.T
    out *= 0.5
    return out


def ekf_predict(model: Dynamics, state: EKFState, u: ArrayLike, Q: Array) -> EKFState:
    """A-priori step (14), (15): theta^- = F(theta, u), P^- = Phi P Phi^T + Q with Phi from (16)."""
    Phi = model.jac_theta(state.theta, u)
    return EKFState(model.step(state.theta, u), propagate_covariance(Phi, state.P, Q))


def _gain(S: Array, PCt: Array) -> Array:
    """K = P C^T S^{-1} by LAPACK's Cholesky solve (S = C P C^T + R is symmetric positive definite).

    Called directly: numpy's general solver costs four times as much at p = 3.
    """
    _, x, info = _dposv(S, PCt.T)
    if info != 0:  # not positive definite in floating point: the general solver (raises if singular)
        return np.asarray(np.linalg.solve(S, PCt.T).T, float)
    return np.asarray(x, float).T


def ekf_update(state: EKFState, y: ArrayLike, C: Array, R: Array, gate: float,
               consider: int = 0) -> tuple[EKFState, UpdateInfo]:
    """Measurement update (13) in Joseph form, leaving out missing or gated readings.

    ``consider`` > 0: the last ``consider`` entries of the state are "consider" states (Schmidt-Kalman):
    their rows of the gain are 0, so the readings do not move them, while their uncertainty still widens the
    others' gain through the cross-covariance; the Joseph form keeps P right for such a gain.

    Parameters
    ----------
    state : a-priori estimate (theta^-, P^-)
    y : (p,) readings in K; NaN / inf = missing
    C : (p, n) output matrix phi(xi_i)^T (12b)
    R : (p, p) measurement noise covariance in K^2
    gate : innovation gate in standard deviations of S_ii = (C P C^T + R)_ii; ``np.inf`` = off
    """
    yv = np.asarray(y, float)
    innov = yv - C @ state.theta
    PCt_full = state.P @ C.T
    S_full = C @ PCt_full + R
    normalized = np.abs(innov) / np.sqrt(S_full.diagonal())
    finite = np.isfinite(yv)
    used = finite & (normalized <= gate)
    all_used = bool(used.all())
    if not all_used and finite.sum() >= 2 and not used.any():
        # every working TC disagrees with the estimate: the estimate is wrong, not all sensors at
        # once.  Inflate P until the closest reading sits at the gate and use them all (recovery).
        scale = float(np.min(normalized[finite]) / gate) ** 2
        log.warning("EKF: all TC readings beyond the gate; covariance inflated x%.3g and readings used", scale)
        state = EKFState(state.theta, scale * state.P)
        PCt_full = scale * PCt_full
        S_full = C @ PCt_full + R
        used = finite
        all_used = bool(used.all())
    if all_used:
        reasons = ("",) * len(yv)
    else:
        reasons = tuple("" if ok else ("missing" if not fin else "gated") for ok, fin in zip(used, finite, strict=True))
        for i, why in enumerate(reasons):  # a missing reading is the loop's to report (once per outage, not 30/s)
            if why:
                log.log(logging.DEBUG if why == "missing" else logging.WARNING, "EKF: TC%d reading %s left out "
                        "(%s, %.1f sigma)", i + 1, yv[i], why, normalized[i])
    if not used.any():
        return state, UpdateInfo(innov, normalized, used, reasons, S_full, np.zeros_like(PCt_full))
    if all_used:  # the normal case: no fancy indexing (it costs more than the algebra at p = 3)
        nu, PCt, S = innov, PCt_full, S_full
    else:
        nu, PCt, S = innov[used], PCt_full[:, used], S_full[np.ix_(used, used)]
    gain = _gain(S, PCt)
    if consider:
        gain[-consider:] = 0.0
    if all_used:
        gain_full = gain
    else:
        gain_full = np.zeros_like(PCt_full)
        gain_full[:, used] = gain
    info = UpdateInfo(innov, normalized, used, reasons, S_full, gain_full)
    theta = state.theta + gain @ nu
    # Joseph form (I - K C) P (I - K C)^T + K R K^T, expanded with S = C P C^T + R:
    #   P - K (P C^T)^T - (P C^T) K^T + K S K^T = P - U V^T,  U = [K, P C^T - K S],  V = [P C^T, K],
    # one rank-2p product in O(n^2 p), valid for any gain K (the point of the Joseph form).
    U = np.concatenate((gain, PCt - gain @ S), axis=1)
    V = np.concatenate((PCt, gain), axis=1)
    P = state.P - U @ V.T
    P += P.T  # exactly symmetric (U V^T is, up to rounding)
    P *= 0.5
    return EKFState(theta, P), info


class Estimator:
    """The EKF of section 3.2 for a :class:`twin.model.discrete.DiscreteModel` and the three TCs xi_1..3.

    Holds the current estimate; ``update(y)`` at each sample, then ``predict(u)`` with the input
    applied until the next sample (or ``step(y, u_prev)`` which does both in the paper's order).

    Parameters
    ----------
    model : the discrete-time model (12a)
    cfg : furnace config (``ekf`` weights, TC positions xi_1..3)
    theta0 : initial estimate theta_0 in K, (n,) or a scalar for a uniform field
    """

    def __init__(self, model: Dynamics, cfg: FurnaceConfig, theta0: ArrayLike) -> None:
        e = cfg.ekf
        self.model = model
        self.cfg = cfg
        fe = model.fe  # type: ignore[attr-defined]
        n = fe.n
        th = np.asarray(theta0, float)
        self.state = EKFState(np.full(n, float(th)) if th.ndim == 0 else th.copy(), e.p0 * np.eye(n))
        self.Q = process_noise(fe.M, e.q0, e.q1)
        self.C = fe.C(np.asarray(cfg.tc_positions()[:3]))
        self.R = e.r0 * np.eye(self.C.shape[0])
        self.gate = e.innovation_gate
        self.last_info: UpdateInfo | None = None
        self._updated = False
        self._phi: NDArray[np.floating[Any]] | None = None  # cached Jacobian (16), see _jacobian
        # Phi P Phi^T (15) in single precision by default: Phi = I + O(t_s), so each entry of the
        # product is rounded like P's own entries (~1e-7 relative per step), against a process
        # noise of 0.55 K^2 on Q's diagonal added at every step (default furnace).  Measured over
        # a 240 s heat-up: P within 1.3e-4 of its largest entry of the float64 filter, the
        # estimate within 1.2 mK (tests/estimation/test_ekf_plant.py); the two products cost half as much.
        self._cov_dtype = np.float32 if e.covariance_precision == "single" else np.float64
        self._phi_theta = self.state.theta
        self._phi_model: Dynamics | None = None

    def set_model(self, model: Dynamics) -> None:
        """Switch the model (e.g. oscillation toggled); keeps the estimate and covariance."""
        self.model = model

    def update(self, y: ArrayLike) -> EKFState:
        """Measurement update (13) with the readings of TC1..3 (K); faulty readings are left out."""
        self.state, self.last_info = ekf_update(self.state, y, self.C, self.R, self.gate)
        self._updated = True
        return self.state

    def predict(self, u: ArrayLike) -> EKFState:
        """Propagate to the next sample (14), (15) with the group fractions u held over t_s."""
        theta = self.state.theta
        P = propagate_covariance(self._jacobian(theta, u), self.state.P, self.Q)
        self.state = EKFState(self.model.step(theta, u), P)
        return self.state

    def _jacobian(self, theta: Array, u: ArrayLike) -> NDArray[np.floating[Any]]:
        """Phi of eq. (16), re-evaluated when a node has moved more than ``ekf.jacobian_tolerance`` K.

        Phi depends on theta only through the radiation term A diag(4 T^3) M_theta (T = M_theta
        theta is a convex combination of the nodes, so no T moves more than the nodes do).  With
        the default 2 K, 4 T^3 changes by at most 3 * 2 / T, 0.6 % at 1000 K, between evaluations.
        Measured against the paper's filter (Jacobian at every sample) over a 240 s heat-up on the
        plant: P differs by at most 5e-3 of its largest entry and the estimate by 4 mK, against
        1 K of TC noise (tests/estimation/test_ekf_plant.py), while the loop skips the Jacobian on ~80 % of
        the samples (it was a third of the EKF's time).  0 evaluates it at every sample.
        Valid for models whose Jacobian does not depend on u, such as the input-affine (12a).
        """
        tol = self.cfg.ekf.jacobian_tolerance
        if (
            self._phi is None
            or self._phi_model is not self.model
            or float(np.abs(theta - self._phi_theta).max()) > tol
        ):
            self._phi = np.asarray(self.model.jac_theta(theta, u), self._cov_dtype)
            self._phi_theta = theta.copy()
            self._phi_model = self.model
        return self._phi

    def step(self, y: ArrayLike, u_prev: ArrayLike) -> EKFState:
        """Predict with the input of the last interval (skipped at the first call), then update."""
        if self._updated:
            self.predict(u_prev)
        return self.update(y)

    def estimate_at(self, points: ArrayLike) -> Array:
        """Estimated temperature (K) at absolute points (n, 2) in m, e.g. TC4 or a profile."""
        return self.model.fe.phi(points) @ self.state.theta  # type: ignore[attr-defined]


def ekf_step_ms(cfg: FurnaceConfig, radiation: object, repeats: int = 200) -> float:
    """Median wall time (ms) of one EKF predict + update on the fixed-specimen model (benchmark).

    The readings come from the model itself heating up (so no reading is gated and the timing is
    that of the normal path); the estimator starts 20 K off.
    """
    from twin.model.discrete import discrete_model

    model = discrete_model(cfg, radiation, None)  # type: ignore[arg-type]
    T0 = cfg.specimen.initial_temperature
    est = Estimator(model, cfg, T0 + 20.0)
    u = np.full(model.m, 0.5)
    truth = np.full(model.n, T0)
    times = []
    for _ in range(repeats):
        truth = model.step(truth, u)
        y = est.C @ truth
        t0 = time.perf_counter()
        est.predict(u)
        est.update(y)
        times.append(time.perf_counter() - t0)
    return 1000.0 * float(np.median(times))
