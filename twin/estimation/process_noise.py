"""The covariance the twin *reports*: the error covariance of its (suboptimal) filter under measured model error.

The filter's Q (``[ekf] q0, q1``, paper section 3.2) is a tuning knob for tracking, not a statement about the
model's error; its P is therefore not the covariance of the estimate's error.  For an arbitrary gain L_j
(the filter's own, applied as it is) and a process noise Q_rep that stands for the measured model error,
the error covariance of the estimate obeys (Joseph form, exact for any gain)

    P^-_{j+1} = Phi_j P_j Phi_j^T + Q_rep                                    (15) with Q_rep
    P_j = (I - L_j C) P^-_j (I - L_j C)^T + L_j R L_j^T                      (13)

with the filter's Phi_j (16), C (12b) and R.  :class:`ReportedCovariance` propagates this second covariance
beside the filter's, so the estimate stays bit for bit what it was and only the reported uncertainty changes.
Q_rep = q0 (q1 sign(M) + 1 1^T)^2 with the constants of ``[ekf.model_error]`` (the filter's form; the
parameters of a calibrating filter keep the filter's random walk).

NIS: nu^T S_rep^{-1} nu / p over the p readings used, S_rep = C P^- C^T + R (1 on average when consistent).

**The thermocouples' fixed deviations (Schmidt-Kalman "consider" states).**  A TC reads
y_i = C_i theta + beta_i tol(y_i) + v_i with a deviation beta_i that stays the same for the whole run
(:mod:`twin.estimation.thermocouple_tolerance`, variance 1/3).  White process noise cannot stand for a constant
error: the filter pulls its estimate towards the biased readings, and the error that leaves is common to the
whole field and never averages out.  With ``tc_tolerance`` the reported covariance is that of the augmented
error eps = (theta_hat - theta, -beta) (Brown and Hwang 2012, "consider" filter; Schmidt 1966): the filter's
gain has zero rows for beta (it does not estimate them, so the estimate is unchanged), and

    Phi_a = [[Phi, 0], [0, I]],   Q_a = [[Q_rep, 0], [0, 0]],   C_a = [C, diag(tol(y))],   L_a = [L; 0]

in the same Joseph form, which is exact for this gain.  The innovation's covariance then includes the
deviations as well: S_rep = C_a P^- C_a^T + R.

**The model's own bias (consider states as well).**  Part of the model's error is not white either: on a fixed
specimen the model's steady heat balance is off by a forcing that stays the same for the run (the truth's lamp
bands between the node lines, its view factors), so its one-step defect has a mean.  With ``bias_shape`` G (m, k)
and ``bias_variance`` (k,) the reported covariance carries that forcing as k constant coefficients c,
theta_{j+1} = F(theta_j, u_j) + s_j G c + w_j, unknown to the filter (its gain has zero rows for c;
s_j = (T_j / T_ref)^p with T_j the mean of the estimated nodes: the bias grows with the temperature; p = 0:
constant):

    Phi_a = [[Phi, 0, s_j G], [0, I, 0], [0, 0, I]],   P_a0 = blkdiag(P0, beta's, diag(bias_variance))

with C_a = [C, diag(tol(y)), 0].  The TCs correct the bias where they read; the rest (between them) stays in the
error and in its reported covariance (:mod:`twin.estimation.model_bias`: the basis and its measured variance).

Example
-------
>>> import numpy as np
>>> rep = ReportedCovariance(np.eye(2), 0.1 * np.eye(2))
>>> rep.predict(np.eye(2))
>>> rep.update(np.array([[0.5], [0.0]]), np.array([[1.0, 0.0]]), np.eye(1), np.array([1.0]), np.array([True]))
>>> np.round(np.diag(rep.P), 3).tolist(), round(rep.nis, 3)   # (1 - 0.5)^2 1.1 + 0.25, 1.1; 1 / 2.1
([0.525, 1.1], 0.476)
>>> biased = ReportedCovariance(np.eye(1), np.zeros((1, 1)), readings=1, tc_tolerance=(1.5, 0.0))
>>> biased.update(np.array([[0.5]]), np.eye(1), np.eye(1), np.array([0.0]), np.array([True]), np.array([300.0]))
>>> round(float(biased.P[0, 0]), 4)   # 0.25 (1 + 1) + 0.25 * 1.5^2 / 3: half of the deviation goes into the error
0.6875
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.estimation.ekf import process_noise, propagate_covariance
from twin.estimation.thermocouple_tolerance import BETA_VARIANCE, tolerance

Array = NDArray[np.float64]


def reported_process_noise(M: Array, model_error: Any, parameter_noise: Array | None = None) -> Array:
    """Q_rep of the module docstring for the nodes (M: the FE mass matrix), with the parameters' block
    (``parameter_noise``, (k, k), e.g. the filter's random walk) appended."""
    Q = process_noise(M, model_error.q0, model_error.q1)
    if parameter_noise is None or not len(parameter_noise):
        return Q
    n, k = Q.shape[0], parameter_noise.shape[0]
    out = np.zeros((n + k, n + k))
    out[:n, :n], out[n:, n:] = Q, parameter_noise
    return out


class ReportedCovariance:
    """The second covariance of the module docstring: ``predict(Phi)`` and ``update(gain, C, R, nu, used, y)``.

    Parameters
    ----------
    P0 : initial covariance (the filter's)
    Q : Q_rep (same size)
    readings : number of TCs the filter reads (the consider states' count; needed with ``tc_tolerance``)
    tc_tolerance : (fixed K, relative of |t| in C) of the TCs' datasheet: carry their deviations as consider
        states (module docstring); None: the readings are taken as unbiased
    bias_shape, bias_variance : G (m, k) and the variances (k,) of the model bias's constant coefficients
        (module docstring); None: no bias carried
    bias_growth : (T_ref K, p) of the bias's growth with the temperature (:meth:`bias_scale`)
    bias_identity : how many of G's last columns are [I; 0] (each node's own forcing; taken as a slice)
    """

    def __init__(self, P0: Array, Q: Array, readings: int = 0, tc_tolerance: tuple[float, float] | None = None,
                 bias_shape: Array | None = None, bias_variance: Array | None = None,
                 bias_growth: tuple[float, float] = (1.0, 0.0), bias_identity: int = 0) -> None:
        P0 = np.asarray(P0, float)
        self.m = P0.shape[0]  # the filter's state; the consider states follow
        self.tc_tolerance = tc_tolerance
        b = readings if tc_tolerance is not None else 0
        self.b = b  # the TCs' deviations, then the model bias's k coefficients
        #: G (m, k) of the model bias (module docstring), None: no bias carried
        self.G: Array | None = None
        #: (T_ref K, p): the bias's forcing at the mean temperature T is (T / T_ref)^p times its value at T_ref
        self.bias_growth = bias_growth
        k = 0
        if bias_shape is not None and bias_variance is not None and len(bias_variance):
            self.G = np.asarray(bias_shape, float)
            k = self.G.shape[1]
            if self.G.shape[0] != self.m or len(bias_variance) != k:
                raise ValueError(f"bias_shape must be ({self.m}, k) and bias_variance (k,): "
                                 f"{self.G.shape}, {len(bias_variance)}")
        self.P = np.zeros((self.m + b + k, self.m + b + k))
        self.P[: self.m, : self.m] = P0
        self.P[self.m: self.m + b, self.m: self.m + b] = BETA_VARIANCE * np.eye(b)
        self.P[self.m + b:, self.m + b:] = np.diag(np.asarray(bias_variance if k else [], float))
        # the consider states' block never changes (zero gain rows, identity dynamics): G P_cz and G P_cc G^T of
        # predict are constants
        if self.G is not None:
            c = self.m + b
            self._G_Pcz = self.G @ self.P[c:, self.m:]
            self._G_Pcc_Gt = self._G_Pcz[:, b:] @ self.G.T
            # the last ``bias_identity`` columns of G are [I; 0] (each node's own forcing): P_xc G^T takes them as
            # a slice instead of a product (the dense product doubled the cost of a predict)
            self._n_id = bias_identity
            self._G_dense = self.G[:, : k - bias_identity]
            if bias_identity and not (np.array_equal(self.G[:bias_identity, k - bias_identity:], np.eye(bias_identity))
                                      and not self.G[bias_identity:, k - bias_identity:].any()):
                raise ValueError("bias_identity: the last columns of bias_shape must be [I; 0]")
        self.Q = np.asarray(Q, float)
        #: NIS of the last update against the reported covariance (NaN when no reading was used)
        self.nis = float("nan")

    def bias_scale(self, temperature: float | None) -> float:
        """s_j of the module docstring: (T / T_ref)^p of ``bias_growth`` at the mean temperature T (K) of the
        estimate; 1 without a bias, without growth or without a temperature."""
        T_ref, p = self.bias_growth
        if self.G is None or not p or temperature is None:
            return 1.0
        return float((temperature / T_ref) ** p)

    def predict(self, Phi: NDArray[np.floating[Any]], temperature: float | None = None) -> None:
        """P^- = Phi P Phi^T + Q_rep (15); the deviations stay what they were (Phi_a of the module docstring);
        ``temperature`` (K, the estimate's mean) sets the bias's growth s_j (:meth:`bias_scale`)."""
        bias_scale = self.bias_scale(temperature)
        m = self.m
        if self.P.shape[0] == m:
            self.P = propagate_covariance(Phi, self.P, self.Q)
            return
        P = np.empty_like(self.P)  # every block is written below
        P[m:, m:] = self.P[m:, m:]
        P[:m, :m] = propagate_covariance(Phi, self.P[:m, :m], self.Q)
        P[:m, m:] = np.asarray(Phi @ self.P[:m, m:].astype(Phi.dtype), float)
        if self.G is not None:  # the bias's forcing G c enters the error: Phi_a's G block
            c, n_id = m + self.b, self._n_id
            X = P[:m, c: P.shape[0] - n_id] @ (bias_scale * self._G_dense.T)  # (Phi P_xc) (s G)^T
            if n_id:
                X[:, :n_id] += bias_scale * P[:m, P.shape[0] - n_id:]
            P[:m, :m] += X + X.T + bias_scale**2 * self._G_Pcc_Gt
            P[:m, m:] += bias_scale * self._G_Pcz
        P[m:, :m] = P[:m, m:].T
        self.P = P

    def update(self, gain: Array, C: Array, R: Array, innovation: Array, used: NDArray[np.bool_],
               readings: Array | None = None) -> None:
        """Joseph form (13) with the filter's gain (n, p; zero columns for readings left out) and the NIS;
        ``readings`` (K, the TCs' values) set tol(y) of the consider states (required with them)."""
        b, z = self.b, self.P.shape[0] - self.m
        if b:
            if readings is None:
                raise ValueError("the TCs' deviations are carried: update needs the readings")
            tol = tolerance(readings, *self.tc_tolerance or (0.0, 0.0))
            if not np.isfinite(tol).all():  # a missing reading: no deviation to carry
                tol = np.nan_to_num(tol, nan=0.0)
            C = np.concatenate([C, np.diag(tol)], axis=1)
        if z > b:  # the TCs read the field, not the bias's coefficients
            C = np.concatenate([C, np.zeros((C.shape[0], z - b))], axis=1)
        if z:
            gain = np.concatenate([gain, np.zeros((z, gain.shape[1]))], axis=0)
        PCt = self.P @ C.T
        S = C @ PCt + R
        if used.all():  # the normal case: no fancy indexing (it costs more than the algebra at p = 3)
            self.nis = float(innovation @ np.linalg.solve(S, innovation)) / len(used)
        elif used.any():
            nu, Su = innovation[used], S[np.ix_(used, used)]
            self.nis = float(nu @ np.linalg.solve(Su, nu)) / int(used.sum())
        else:
            self.nis = float("nan")
            return
        # (I - L C) P (I - L C)^T + L R L^T = P - L PCt^T - PCt L^T + L S L^T; PCt L^T is (L PCt^T)^T to the
        # bit (each entry the same p products summed in the same order), so it is formed once
        LPCt = gain @ PCt.T
        P = self.P - LPCt
        P -= LPCt.T
        P += (gain @ S) @ gain.T
        P += P.T
        P *= 0.5
        self.P = P
