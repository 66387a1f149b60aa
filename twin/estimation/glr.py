"""Generalized likelihood ratio (GLR) tests of additive faults on the EKF's innovations.

Willsky & Jones (IEEE TAC 21, 1976, "A generalized likelihood ratio approach to the detection and
estimation of jumps in linear systems"): a fault of unknown size f that starts at sample j0 adds
f sigma_j to the innovations nu_j of the filter (section 3.2, eq. 13), where the *signature*
sigma_j follows from the filter's own gains.  With s the fault's effect on the prior estimate
(theta^-  shifted by f s^-), per hypothesis h and sample j >= j0::

    sigma_j = a_h,j - C s^-_j                 (innovation signature)
    s^+_j   = s^-_j + L_j sigma_j             (the update (13) spreads it with the gain L_j)
    s^-_j+1 = Phi_j s^+_j + b_h,j             (the prediction (14), linearised (16))

- sensor offset on TC k: a = e_k, b = 0;  sensor drift: a = (j - j0) t_s e_k, b = 0;
- lamp group i losing the fraction f of its nominal power: a = 0, b = dF/du_i u_i,j
  (the model heats with power the plant did not get);
- every group losing the fraction f ("common"): a = 0, b = dF/du u_j.  The model's own errors
  that act like a loss of heating everywhere (the constant c_p of the reduced model misses the
  Curie peak of the steel, eqs. 9-11) fit this one; a single group's fault must beat it;
- the specimen's heat capacity off by the fraction f ("capacity"): a = 0, b = the model's own
  increment F(theta_j, u_j) - theta_j (the plant moves by less where c_p is larger, e.g. at the
  Curie point, which the reduced model's constant c_p misses).

With the whitened sums A = sum sigma^T S^-1 nu and B = sum sigma^T S^-1 sigma over the readings
used for testing, the maximum-likelihood size is f = A / B (standard deviation 1 / sqrt(B)) and the
log-likelihood ratio against "no fault" is lambda = A^2 / B (chi^2 with one degree of freedom
under no fault when the innovations are white).

A :class:`SignatureBanks` holds one bank of hypotheses per candidate onset, started every
``onset_every`` samples and dropped after ``window`` samples (a finite-memory GLR: the unknown
onset is maximised over the banks alive).

Example
-------
A scalar state measured directly (C = 1), a steady filter (L = 0.5, Phi = 1): an offset of 2 K on
the only TC is found with its size.

>>> import numpy as np
>>> banks = SignatureBanks(n=1, p=1, kinds=("offset",), columns=(0,), onset_every=1000, window=1000, t_s=0.1)
>>> C, L, Phi, S = np.ones((1, 1)), np.array([[0.5]]), np.eye(1), np.eye(1)
>>> for j in range(20):
...     banks.update(j, C, np.array([2.0 * 0.5 ** j]), S, L, np.array([True]))  # the filter absorbs it
...     banks.predict(Phi, np.zeros((1, 1)), np.zeros(1))
>>> best = banks.best(min_age=1)
>>> round(best.size, 3), round(best.llr, 1)
(2.0, 5.3)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Candidate:
    """The most likely fault of one bank: hypothesis index, onset sample, size, its sigma and lambda."""

    hypothesis: int
    onset: int
    age: int
    size: float
    sigma: float
    llr: float
    runner_up: int  # the next most likely hypothesis of the same bank (-1 if none)
    runner_up_llr: float


class SignatureBanks:
    """Fault signatures and GLR sums for H hypotheses at several candidate onsets (module docstring).

    Parameters
    ----------
    n, p : state size, number of readings (TC1..3)
    kinds : per hypothesis "offset", "drift" (column = the TC index), "lamp" (column = the group index) or
        "common" (all groups) or "capacity" (column ignored for both)
    columns : per hypothesis the TC or group index
    onset_every : a new bank every this many samples
    window : a bank is dropped after this many samples
    t_s : sampling time (s), for the drift ramp
    """

    def __init__(self, n: int, p: int, kinds: tuple[str, ...], columns: tuple[int, ...], *, onset_every: int,
                 window: int, t_s: float) -> None:
        self.n, self.p, self.H = n, p, len(kinds)
        self.kinds, self.columns = kinds, np.asarray(columns, int)
        self.onset_every, self.window, self.t_s = int(onset_every), int(window), float(t_s)
        self._sensor = np.array([k in ("offset", "drift") for k in kinds])
        self._drift = np.array([k == "drift" for k in kinds])
        self._lamp = np.array([k == "lamp" for k in kinds])
        self._common = np.array([k == "common" for k in kinds])
        self._capacity = np.array([k == "capacity" for k in kinds])
        self._layouts: dict[int, _Layout] = {}  # per number of banks (issue 21: made once, not per sample)
        self._onsets: list[int] = []
        self._j = -1  # the last updated sample
        self._s = np.zeros((n, 0))  # (n, banks * H), bank-major
        self._A = np.zeros(0)
        self._B = np.zeros(0)

    def _layout(self, nb: int) -> _Layout:
        """The columns of each kind of hypothesis over ``nb`` banks (they depend on nb alone)."""
        lay = self._layouts.get(nb)
        if lay is None:
            sens = np.flatnonzero(np.tile(self._sensor, nb))
            cols = np.tile(self.columns, nb)
            lamp = np.flatnonzero(np.tile(self._lamp, nb))
            lay = self._layouts[nb] = _Layout(
                sensor=sens, sensor_rows=cols[sens], sensor_drift=np.tile(self._drift, nb)[sens],
                lamp=lamp, lamp_groups=cols[lamp], common=np.flatnonzero(np.tile(self._common, nb)),
                capacity=np.flatnonzero(np.tile(self._capacity, nb)))
        return lay

    def reset(self) -> None:
        """Forget every bank (after a decision the filter's configuration changed)."""
        self._onsets = []
        self._s = np.zeros((self.n, 0))
        self._A = np.zeros(0)
        self._B = np.zeros(0)

    @property
    def n_banks(self) -> int:
        return len(self._onsets)

    def _start_or_drop(self, j: int) -> None:
        if self._onsets and j - self._onsets[0] >= self.window:
            H = self.H
            self._onsets.pop(0)
            self._s, self._A, self._B = self._s[:, H:], self._A[H:], self._B[H:]
        if j % self.onset_every == 0:
            self._onsets.append(j)
            self._s = np.concatenate([self._s, np.zeros((self.n, self.H))], axis=1)
            self._A = np.concatenate([self._A, np.zeros(self.H)])
            self._B = np.concatenate([self._B, np.zeros(self.H)])

    def update(self, j: int, C: Array, nu: Array, S: Array, L: Array, tested: NDArray[np.bool_]) -> None:
        """The measurement update of sample j: add to the GLR sums and spread the signatures with the gain.

        C (p, n), nu (p,) innovations (NaN where no reading), S (p, p) their covariance, L (n, p) the
        gain the filter applied, ``tested``: readings that enter the test sums.
        """
        self._start_or_drop(j)
        self._j = j
        if not self._onsets:
            return
        H, nb = self.H, len(self._onsets)
        a = np.zeros((self.p, nb * H))
        lay = self._layout(nb)
        ages = j - np.repeat(np.asarray(self._onsets), H)[lay.sensor]
        a[lay.sensor_rows, lay.sensor] = np.where(lay.sensor_drift, ages * self.t_s, 1.0)
        sigma = a - C @ self._s  # (p, nb H)
        obs = tested & np.isfinite(nu)
        if obs.any():
            So = S[np.ix_(obs, obs)]
            w = np.linalg.solve(So, sigma[obs])  # S^-1 sigma, (|obs|, nb H)
            self._A += w.T @ nu[obs]
            self._B += np.einsum("ij,ij->j", sigma[obs], w)
        self._s += L @ np.where(np.isfinite(sigma), sigma, 0.0)

    def predict(self, Phi: Array, Gamma: Array, u: Array, increment: Array | None = None) -> None:
        """The prediction of the same sample: s = Phi s + b, b = dF/du_i u_i for the lamp hypotheses.

        Phi (n, n), Gamma (n, m) = dF/du of the nominal model, u (m,) the commanded group powers,
        ``increment`` (n,) F(theta, u) - theta of the estimate (for the capacity hypothesis).
        """
        if not self._onsets:
            return
        self._s = Phi @ self._s
        lay = self._layout(len(self._onsets))
        lamp, common, capacity = lay.lamp, lay.common, lay.capacity
        if lamp.size:
            g = lay.lamp_groups
            self._s[:, lamp] += Gamma[:, g] * np.asarray(u, float)[g]
        if common.size:
            self._s[:, common] += (Gamma @ np.asarray(u, float))[:, None]
        if capacity.size and increment is not None:
            self._s[:, capacity] += np.asarray(increment, float)[:, None]

    def table(self) -> Table | None:
        """lambda, size and its sigma of every hypothesis (columns) at every live onset (rows), with the
        onsets and ages (samples); ``None`` before the first bank."""
        if not self._onsets:
            return None
        H = self.H
        A, B = self._A.reshape(-1, H), self._B.reshape(-1, H)
        with np.errstate(divide="ignore", invalid="ignore"):
            ok = B > 1e-12
            llr = np.where(ok, A**2 / np.where(ok, B, 1.0), 0.0)
            size = np.where(ok, A / np.where(ok, B, 1.0), 0.0)
            sigma = np.where(ok, 1.0 / np.sqrt(np.where(ok, B, 1.0)), np.inf)
        onsets = np.asarray(self._onsets)
        return Table(llr, size, sigma, onsets, self._j - onsets)

    def best(self, min_age: int) -> Candidate | None:
        """The hypothesis and onset of largest lambda among banks at least ``min_age`` samples old, with the
        runner-up: the largest lambda of any other hypothesis at any onset."""
        tab = self.table()
        if tab is None:
            return None
        eligible = np.where((tab.ages >= min_age)[:, None], tab.llr, 0.0)
        if not np.any(eligible > 0):
            return None
        k, h = np.unravel_index(int(np.argmax(eligible)), eligible.shape)
        return tab.candidate(int(k), int(h), tab.llr)


@dataclass(frozen=True)
class _Layout:
    """Columns (bank-major) of the sensor hypotheses with their TC rows and drift flags, of the lamp hypotheses
    with their groups, of the common and capacity hypotheses, over a number of banks."""

    sensor: NDArray[np.intp]
    sensor_rows: NDArray[np.intp]
    sensor_drift: NDArray[np.bool_]
    lamp: NDArray[np.intp]
    lamp_groups: NDArray[np.intp]
    common: NDArray[np.intp]
    capacity: NDArray[np.intp]


@dataclass(frozen=True)
class Table:
    """What :meth:`SignatureBanks.table` returns: (banks, H) arrays and per-bank onsets and ages."""

    llr: Array
    size: Array
    sigma: Array
    onsets: NDArray[np.int64]
    ages: NDArray[np.int64]

    def candidate(self, k: int, h: int, competitors: Array) -> Candidate:
        """Bank k's hypothesis h, its runner-up the best other hypothesis (any onset) of ``competitors``."""
        other = competitors.copy()
        other[:, h] = -np.inf
        kk, ru = np.unravel_index(int(np.argmax(other)), other.shape)
        ru_llr = float(other[kk, ru]) if np.isfinite(other[kk, ru]) else 0.0
        return Candidate(hypothesis=h, onset=int(self.onsets[k]), age=int(self.ages[k]), size=float(self.size[k, h]),
                         sigma=float(self.sigma[k, h]), llr=float(competitors[k, h]),
                         runner_up=int(ru) if other.shape[1] > 1 else -1, runner_up_llr=max(ru_llr, 0.0))
