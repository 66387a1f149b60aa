"""Joint state and parameter estimation, at the specimen's position (extends the paper's EKF, section 3.2).

The estimator learns a few slowly varying furnace parameters p (relative deviations of the model:
lamp efficiency, emissivity, convection; :class:`twin.model.tables.Parameters`) from TC1-3 and the
applied powers, as random walks in an augmented state x = [theta; p]:

    x_{j+1} = [F(theta_j, u_j; eta_j, p_j); p_j]                      (12a, 14)
    Phi_x = [[dF/dtheta, dF/dp], [0, I]],                              (16)
    Q_x = blkdiag(Q, t_s diag(r_p^2)),   C_x = [C, 0],                 (15), (12b)

and the measurement update (13) of :func:`twin.estimation.ekf.ekf_update` (Joseph form, gating) on
x; p is then held within its physical bounds (a clipped estimate keeps its covariance).  With no
calibrated parameter and the averaged motion this is the paper's filter
(:class:`twin.estimation.ekf.Estimator`), step for step.

The model is a :class:`twin.model.parametric.ParametricModel`: averaged over the oscillation
(eq. 11) or at the known position eta(t_j).  Phi is re-evaluated per table position when a node
has moved more than ``ekf.jacobian_tolerance`` K (or p moved), as the paper's estimator does for
the whole Phi; between table positions the per-position pieces are blended with the hat weights.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> from twin.model.parametric import Evaluation, ParametricModel
>>> from twin.model.tables import model_tables
>>> from twin.radiation import radiation_model
>>> cfg = small_config()
>>> model = ParametricModel(model_tables(cfg, radiation_model(cfg)), None, calibrated=("lamp_efficiency",))
>>> est = JointEstimator(model, cfg, 300.0)
>>> est.predict(np.full(6, 0.5), 0.0).theta.shape, est.parameters.lamp_efficiency, est.parameter_sigma.shape
((105,), 0.0, (1,))
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.estimation.ekf import EKFState, UpdateInfo, ekf_update, process_noise, propagate_covariance
from twin.estimation.model_bias import node_shape
from twin.estimation.process_noise import ReportedCovariance, reported_process_noise
from twin.model.parametric import Evaluation, ParametricModel
from twin.model.tables import PARAMETERS, Parameters

Array = NDArray[np.float64]

#: A parameter change (relative deviation) that re-evaluates the parameter-dependent parts of Phi: the
#: radiation part of eq. (16) changes by about as much (0.5 %) as it does for the 2 K node tolerance
#: (4 T^3 changes by 3 * 2 K / T = 0.6 % at 1000 K).
PARAMETER_TOLERANCE = 5e-3


class JointEstimator:
    """EKF on [theta; p] with a position-aware or averaged :class:`ParametricModel` (module docstring).

    Parameters
    ----------
    model : the estimator's model (its ``calibrated`` names the parameters in the state)
    cfg : furnace config (``ekf`` weights, ``calibration`` priors and bounds, TC positions)
    theta0 : initial temperature estimate (K), (n,) or a scalar
    p0 : initial parameters (default: the nominal model, all 0)
    """

    def __init__(self, model: ParametricModel, cfg: FurnaceConfig, theta0: ArrayLike,
                 p0: Parameters | None = None) -> None:
        e = cfg.ekf
        self.cfg = cfg
        self.model = model
        n, k = model.n, len(model.calibrated)
        self.n, self.k = n, k
        th = np.asarray(theta0, float)
        p_all = (p0 or Parameters()).as_array()
        self._index = [PARAMETERS.index(name) for name in model.calibrated]
        self._p_full = p_all.copy()
        x0 = np.concatenate([np.full(n, float(th)) if th.ndim == 0 else th.copy(), p_all[self._index]])
        cal = cfg.calibration
        sigma0 = np.array([getattr(cal.prior_sigma, name) for name in model.calibrated])
        self._rw = np.array([getattr(cal.random_walk, name) for name in model.calibrated])
        self._lo = np.array([getattr(cal.bounds, name)[0] for name in model.calibrated])
        self._hi = np.array([getattr(cal.bounds, name)[1] for name in model.calibrated])
        P0 = np.zeros((n + k, n + k))
        P0[:n, :n] = e.p0 * np.eye(n)
        P0[n:, n:] = np.diag(sigma0**2)
        self._x = EKFState(x0, P0)
        fe = model.fe
        self.Q = np.zeros((n + k, n + k))
        self.Q[:n, :n] = process_noise(fe.M, e.q0, e.q1)
        self.Q[n:, n:] = np.diag(self._rw**2 * model.t_s)
        C = fe.C(np.asarray(cfg.tc_positions()[:3]))
        self.C = np.concatenate([C, np.zeros((C.shape[0], k))], axis=1)
        self.R = e.r0 * np.eye(C.shape[0])
        self.gate = e.innovation_gate
        self.last_info: UpdateInfo | None = None
        #: the covariance the twin reports (twin.estimation.process_noise), None: the filter's own P is reported
        self.reported: ReportedCovariance | None = None
        if e.model_error is not None:
            # the specimen's mode: the model's error is smaller when it moves (averaged over the lamps)
            osc = model.oscillation
            me = e.model_error.for_mode(osc is not None and bool(osc.enabled))
            self.reported = ReportedCovariance(
                P0, reported_process_noise(fe.M, me, self.Q[n:, n:]), readings=C.shape[0],
                tc_tolerance=(me.tc_tolerance_fixed, me.tc_tolerance_relative) if me.tc_bias else None,
                bias_shape=node_shape(fe, me.bias_degree if me.bias_variance else None, k, me.bias_node_variance > 0),
                bias_variance=np.asarray(me.bias_variances(n), float),
                bias_growth=(me.bias_temperature, me.bias_exponent),
                bias_identity=n if me.bias_node_variance > 0 else 0)
        self._cov_dtype = np.float32 if e.covariance_precision == "single" else np.float64
        self._tol = e.jacobian_tolerance
        self._lin: tuple[float, Array] | None = None  # (convection it was built for, I + t_s L(p))
        self._rad: dict[int, tuple[Array, float, Array]] = {}  # id(node) -> (theta, p_e, t_s A diag(4T^3) M)
        # the assembled theta part of Phi, reused while no piece was rebuilt and the positions' weights are the
        # same (the averaged model, a fixed specimen): (version of the pieces, weights, J: in the covariance dtype
        # for a constant capacity, else the float64 sum the capacity scaling of each sample is applied to)
        self._pieces_version = 0
        self._assembled: tuple[int, tuple[float, ...], NDArray[Any]] | None = None
        #: dF/dp of the last prediction (n, k), the upper right block of Phi_x (16); zeros before the first
        self.parameter_jacobian: Array = np.zeros((n, k))

    # ---- the estimate
    @property
    def state(self) -> EKFState:
        """The temperature part: theta (n,) and its covariance (n, n)."""
        n = self.n
        return EKFState(self._x.theta[:n], self._x.P[:n, :n])

    @property
    def parameters(self) -> Parameters:
        """The current parameter estimates (the uncalibrated ones stay at their initial values)."""
        p = self._p_full.copy()
        p[self._index] = self._x.theta[self.n:]
        return Parameters.from_array(p)

    @property
    def parameter_sigma(self) -> Array:
        """Standard deviations (k,) of the calibrated parameters, in the order of ``model.calibrated``."""
        return np.sqrt(np.clip(np.diag(self._x.P)[self.n:], 0.0, None))

    @property
    def reported_P(self) -> Array:
        """The temperature part (n, n) of the covariance the twin reports (module docstring of
        :mod:`twin.estimation.process_noise`; the filter's own P without ``[ekf.model_error]``)."""
        n = self.n
        return self._x.P[:n, :n] if self.reported is None else self.reported.P[:n, :n]

    @property
    def nis(self) -> float:
        """Normalised innovation squared of the last update per reading used, against the reported
        covariance (NaN before the first update or when no reading was used)."""
        info = self.last_info
        if self.reported is not None:
            return self.reported.nis
        if info is None or info.S is None or not info.used.any():
            return float("nan")
        nu, S = info.innovation[info.used], info.S[np.ix_(info.used, info.used)]
        return float(nu @ np.linalg.solve(S, nu)) / int(info.used.sum())

    def calibration(self) -> dict[str, dict[str, float]]:
        """``{name: {"value", "sigma"}}`` of the calibrated parameters (product.md ``calibration``)."""
        p, s = self.parameters, self.parameter_sigma
        return {name: {"value": float(getattr(p, name)), "sigma": float(s[i])}
                for i, name in enumerate(self.model.calibrated)}

    def set_model(self, model: ParametricModel) -> None:
        """Switch the model (e.g. oscillation toggled); keeps the estimate, covariance and parameters."""
        if model.calibrated != self.model.calibrated:
            raise ValueError("the new model calibrates other parameters than the estimator's state holds")
        self.model = model
        self._rad.clear()
        self._assembled = None

    # ---- the filter
    def update(self, y: ArrayLike, learn: bool = True) -> EKFState:
        """Measurement update (13) with TC1..3 (K) on the augmented state; p kept within its bounds.
        ``learn=False``: the parameters are consider states (:func:`twin.estimation.ekf.ekf_update`): kept,
        their uncertainty still counted."""
        x, self.last_info = ekf_update(self._x, y, self.C, self.R, self.gate, 0 if learn else self.k)
        info = self.last_info
        if self.reported is not None and info.gain is not None:
            self.reported.update(info.gain, self.C, self.R, info.innovation, info.used, np.asarray(y, float))
        if self.k:
            p = x.theta[self.n:]
            clipped = np.clip(p, self._lo, self._hi)
            if not np.array_equal(p, clipped):
                x = EKFState(np.concatenate([x.theta[:self.n], clipped]), x.P)
        self._x = x
        return self.state

    def predict(self, u: ArrayLike, eta: float = 0.0) -> EKFState:
        """Propagate to the next sample (14), (15) with u held over t_s at the position eta (m)."""
        n = self.n
        theta = self._x.theta[:n]
        p = self.parameters
        e = self.model.evaluate(theta, u, eta, p)
        Phi = self._jacobian(e, eta, p)
        theta_next = theta + self.model.t_s * e.rate
        P = propagate_covariance(Phi, self._x.P, self.Q)
        if self.reported is not None:
            self.reported.predict(Phi, float(np.mean(theta)))  # the bias's growth at the estimate's temperature
        self._x = EKFState(np.concatenate([theta_next, self._x.theta[n:]]), P)
        return self.state

    def _jacobian(self, e: Evaluation, eta: float, p: Parameters) -> NDArray[Any]:
        """Phi_x of the module docstring; the theta part from cached per-position pieces (class docstring)."""
        n, k = self.n, self.k
        model = self.model
        theta = e.theta
        if self._lin is None or abs(self._lin[0] - p.convection) > PARAMETER_TOLERANCE:
            self._lin = (p.convection, model.linear_jacobian(p))
            self._pieces_version += 1
        pieces = []
        for node, w in model.positions(eta):
            cached = self._rad.get(id(node))
            if (cached is None or float(np.abs(theta - cached[0]).max()) > self._tol
                    or abs(cached[1] - p.emissivity) > PARAMETER_TOLERANCE):
                cached = (theta.copy(), p.emissivity, model.radiation_jacobian(node, e.T, p.emissivity))
                self._rad[id(node)] = cached
                self._pieces_version += 1
            pieces.append((w, cached[2]))
        weights = tuple(float(w) for w, _ in pieces)
        hit = self._assembled
        if hit is not None and hit[0] == self._pieces_version and hit[1] == weights:
            J0 = hit[2]  # nothing changed since the last sample: the same sum (0.08 ms per sample saved)
        else:
            J0 = self._lin[1].copy()
            for w, piece in pieces:
                J0 += w * piece
            if e.capacity is None:
                J0 = J0.astype(self._cov_dtype, copy=False)
            self._assembled = (self._pieces_version, weights, J0)
        # with c_p(theta) the capacity scaling moves every sample; the constant-capacity sum J0 it scales is kept
        J = J0 if e.capacity is None else model.with_capacity(J0, e).astype(self._cov_dtype, copy=False)
        if not k:
            return J
        Phi = np.zeros((n + k, n + k), dtype=self._cov_dtype)
        Phi[:n, :n] = J
        self.parameter_jacobian = np.asarray(model.jac_p_of(e), float)
        Phi[:n, n:] = self.parameter_jacobian
        Phi[n:, n:] = np.eye(k)
        return Phi
