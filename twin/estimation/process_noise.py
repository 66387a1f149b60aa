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

Example
-------
>>> import numpy as np
>>> rep = ReportedCovariance(np.eye(2), 0.1 * np.eye(2))
>>> rep.predict(np.eye(2))
>>> rep.update(np.array([[0.5], [0.0]]), np.array([[1.0, 0.0]]), np.eye(1), np.array([1.0]), np.array([True]))
>>> np.round(np.diag(rep.P), 3).tolist(), round(rep.nis, 3)   # (1 - 0.5)^2 1.1 + 0.25, 1.1; 1 / 2.1
([0.525, 1.1], 0.476)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.estimation.ekf import process_noise, propagate_covariance

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
    """The second covariance of the module docstring: ``predict(Phi)`` and ``update(gain, C, R, nu, used)``.

    Parameters
    ----------
    P0 : initial covariance (the filter's)
    Q : Q_rep (same size)
    """

    def __init__(self, P0: Array, Q: Array) -> None:
        self.P = np.array(P0, float)
        self.Q = np.asarray(Q, float)
        #: NIS of the last update against the reported covariance (NaN when no reading was used)
        self.nis = float("nan")

    def predict(self, Phi: NDArray[np.floating[Any]]) -> None:
        """P^- = Phi P Phi^T + Q_rep (15)."""
        self.P = propagate_covariance(Phi, self.P, self.Q)

    def update(self, gain: Array, C: Array, R: Array, innovation: Array, used: NDArray[np.bool_]) -> None:
        """Joseph form (13) with the filter's gain (n, p; zero columns for readings left out) and the NIS."""
        PCt = self.P @ C.T
        S = C @ PCt + R
        if used.any():
            nu, Su = innovation[used], S[np.ix_(used, used)]
            self.nis = float(nu @ np.linalg.solve(Su, nu)) / int(used.sum())
        else:
            self.nis = float("nan")
            return
        # (I - L C) P (I - L C)^T + L R L^T = P - L PCt^T - PCt L^T + L S L^T
        LS = gain @ S
        P = self.P - gain @ PCt.T - PCt @ gain.T + LS @ gain.T
        P += P.T
        P *= 0.5
        self.P = P
