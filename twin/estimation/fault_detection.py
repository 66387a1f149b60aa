"""What the twin's own data says about its sensors and lamps: fault detection and isolation.

The detector sees only what the estimator sees -- the TC readings with their status, the EKF's
innovations, covariance and gain (:class:`twin.estimation.ekf.UpdateInfo`) and the powers the
controller commanded -- never the furnace's injected faults.  Per sample:

1. :meth:`FaultDetector.screen` (before the EKF update) runs the reading tests on TC1..TC4:
   *dropout*: the TC gave no usable reading for ``dropout_s`` while another of TC1..3 did; *stuck*:
   it repeated the same value (to ``flat_tolerance`` K) for ``flat_s`` while real readings carry noise
   and follow the plate.  It returns TC1..3 for the EKF with the TCs found faulty left out (NaN).
   While none of TC1..3 reads, no TC's dropout is counted: the furnace or the link to it is out (an
   outage, which the loop reports), and a TC left out for it would not be used again when the readings
   return (they are re-admitted only once they agree with an estimate that ran blind); a TC that still
   gives nothing ``dropout_s`` after the others came back has dropped out.  Nor is a TC whose reading the
   link could not bring (status ``unlinked``: its subscription on a new connection has not delivered yet).
2. :meth:`FaultDetector.update` (after the update) runs the innovation tests: finite-memory GLR
   tests (:mod:`twin.estimation.glr`) of an offset or a drift on each of TC1..3 and of a lost
   fraction of each lamp group's power ("power that the model cannot explain"), on the readings of
   the TCs in use.  The most likely hypothesis is declared when its log-likelihood ratio exceeds
   ``llr_threshold``, its size is physically relevant (``min_offset``, ``min_drift``,
   ``min_power_loss``) and it beats the runner-up of the same onset by ``llr_margin``.
3. :meth:`FaultDetector.predict` (after the EKF's prediction) moves the signatures on.

With a calibrating estimator (:class:`twin.estimation.joint.JointEstimator`, state x = [theta; p])
the signatures live in the same augmented state: the filter's gain moves p too (a lost lamp group
first looks like a lower lamp efficiency, which the calibration takes up while the reference holds),
and p acts back on theta through dF/dp (Phi_x of eq. 16).  A signature over theta alone misses that
part of the filter's reaction and underestimates the fault (a failed group of the small furnace was
taken as 82 % lost, so derated, instead of 100 %).

What follows a decision (the ride-through, :class:`twin.runs.loop.ClosedLoop`): a faulty TC is left
out of the estimate until it reads consistently again for ``readmit_s``; a lamp group's believed
gain ``lamp_gains`` drops by the estimated loss (to 0 below ``failed_below``: failed), the
estimator is fed the power the lamps deliver, and the controller is re-planned without it.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> from twin.model.discrete import discrete_model
>>> from twin.radiation import radiation_model
>>> cfg = small_config()
>>> det = FaultDetector(cfg, discrete_model(cfg, radiation_model(cfg)))
>>> y = det.screen(0.0, np.array([300.0, np.nan, 300.0, 300.0]), ("good", "bad", "good", "good"))
>>> y.tolist(), det.excluded.tolist()
([300.0, nan, 300.0], [False, False, False])
"""

from __future__ import annotations

import logging
import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.estimation.ekf import UpdateInfo
from twin.estimation.fault_settings import Detection, DetectionSettings
from twin.estimation.glr import Candidate, SignatureBanks

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

TC_NAMES = ("TC1", "TC2", "TC3", "TC4")
N_EKF_TCS = 3
NUISANCES = ("common", "capacity")


class FaultDetector:
    """Reading tests and GLR innovation tests of one run (module docstring).

    Parameters
    ----------
    cfg : the furnace (TC positions, lamp groups, t_s)
    model : the twin's nominal discrete model (``fe``, ``jac_theta``, ``jac_u``): the signatures' Phi, Gamma
    settings : thresholds (defaults: :class:`DetectionSettings`)
    jacobian_every_s : Phi of the signatures is re-evaluated at the estimate this often
    n_parameters : calibrated parameters k in the estimator's state [theta; p] (module docstring)
    """

    def __init__(self, cfg: FurnaceConfig, model: Any, settings: DetectionSettings | None = None, *,
                 jacobian_every_s: float = 1.0, n_parameters: int = 0) -> None:
        self.cfg = cfg
        self.settings = s = settings or DetectionSettings()
        self.t_s = t_s = float(cfg.sampling.t_s)
        self.groups = tuple(g.name for g in cfg.lamps.groups)
        self.model = model
        self.C = np.asarray(model.fe.C(np.asarray(cfg.tc_positions()[:N_EKF_TCS])), float)
        self.k = k = int(n_parameters)
        self._C_x = np.concatenate([self.C, np.zeros((N_EKF_TCS, k))], axis=1)  # C_x = [C, 0] (12b)
        m = len(self.groups)
        # the hypotheses: offset, drift of TC1..3; loss of each group's power; and two the model's own errors
        # look like, never declared: a loss of all groups' power, a heat capacity error (glr module docstring)
        kinds = ("offset",) * N_EKF_TCS + ("drift",) * N_EKF_TCS + ("lamp",) * m + NUISANCES
        cols = tuple(range(N_EKF_TCS)) * 2 + tuple(range(m)) + (0,) * len(NUISANCES)
        self.kinds, self.columns = kinds, cols
        self.targets = TC_NAMES[:N_EKF_TCS] * 2 + self.groups + ("all groups", "heat capacity")
        self.banks = SignatureBanks(model.n + k, N_EKF_TCS, kinds, cols, onset_every=self._n(s.onset_every_s),
                                    window=self._n(s.window_s), t_s=t_s)
        self.lamp_gains = np.ones(m)  # believed fraction of each group's nominal power delivered
        self._rated = np.asarray(cfg.group_matrix, float).sum(axis=0) * cfg.lamps.rated_power  # W per group
        self._u = np.zeros(m)  # the powers commanded last
        self.excluded = np.zeros(N_EKF_TCS, bool)  # TCs left out of the estimate
        self.reasons = [""] * N_EKF_TCS
        self.detections: list[Detection] = []
        self._j = -1
        self._last = np.full(len(TC_NAMES), np.nan)
        self._flat = np.zeros(len(TC_NAMES), int)
        self._unusable = np.zeros(len(TC_NAMES), int)
        self._reported = [""] * len(TC_NAMES)  # reading faults reported for TC1..4 (TC4: report only)
        self._recent: list[list[float]] = [[] for _ in range(N_EKF_TCS)]  # normalised innovations while left out
        self._y = np.full(len(TC_NAMES), np.nan)
        self._pending: list[Detection] = []
        self._jac_every = self._n(jacobian_every_s)
        # the signatures' Phi_x = [[dF/dtheta, dF/dp], [0, I]] (16) and Gamma_x = [dF/du; 0] in the filter's
        # state [theta; p] (plain Phi, Gamma without calibrated parameters); dF/dtheta every jacobian_every_s
        self._Phi_x = np.eye(model.n + k)
        self._phi_ready = False
        self._Gamma_x = self._gamma_x(model)
        self._block: list[Array] = []  # normalised innovations of the current block
        self._block_means: list[Array] = []  # (3,) per finished block, oldest first
        self.inflation = np.ones(N_EKF_TCS)  # kappa per TC (>= 1)
        self._ready = False
        self.innovation_tests = True

    def _n(self, seconds: float) -> int:
        return max(1, int(round(seconds / self.t_s)))

    def _gamma_x(self, model: Any) -> Array:
        gamma = np.asarray(model.jac_u(None, None), float)
        return np.concatenate([gamma, np.zeros((self.k, gamma.shape[1]))])

    def set_model(self, model: Any) -> None:
        """A new nominal model (oscillation switched): signatures restart."""
        self.model = model
        self._Gamma_x = self._gamma_x(model)
        self._Phi_x = np.eye(model.n + self.k)
        self._phi_ready = False
        self.banks.reset()

    def set_innovation_tests(self, enabled: bool) -> None:
        """Run the GLR tests or not (the reading tests always run).  The loop turns them off while the
        estimator's model cannot explain its innovations: the averaged model (eq. 11) of an oscillating
        specimen misses the heating at each position, and while it heats up its innovations are coloured
        enough (kappa up to 30, docs/faults.md) to pass for faults."""
        if enabled != self.innovation_tests:
            self.banks.reset()  # the colour of the innovations (inflation) is followed all along
        self.innovation_tests = enabled

    # ------------------------------------------------------------------ 1. reading tests
    def screen(self, t: float, values: Array, status: tuple[str, ...]) -> Array:
        """Dropout and stuck tests on TC1..TC4; returns TC1..3 for the EKF with left-out TCs as NaN."""
        s = self.settings
        self._j += 1
        y = np.where([st == "good" for st in status], np.asarray(values, float), np.nan)
        usable = np.isfinite(y)
        same = usable & np.isfinite(self._last) & (np.abs(y - self._last) <= s.flat_tolerance)
        self._flat = np.where(same, self._flat + 1, 0)
        isolating = bool(usable[:N_EKF_TCS].any())  # a dropout is one TC's only while another reads
        linked = np.array([st != "unlinked" for st in status])  # the link could not bring it: not the TC's
        self._unusable = np.where(usable, 0, self._unusable + int(isolating) * linked)  # an outage counts for none
        self._last = y
        self._y = y
        if self._reported[3] and usable[3] and self._flat[3] == 0:
            self._reported[3] = ""  # TC4 (never left out: it only validates) reads again
        for i, name in enumerate(TC_NAMES):
            kind, since = "", 0
            if self._unusable[i] >= self._n(s.dropout_s):
                kind, since = "dropout", self._unusable[i] - 1  # samples since the first one without a reading
            elif self._flat[i] + 1 >= self._n(s.flat_s):
                kind, since = "stuck", self._flat[i]
            if not kind or self._reported[i] == kind:
                continue
            self._reported[i] = kind
            onset = t - since * self.t_s
            if kind == "dropout":
                text = f"{name} gives no reading since t = {onset:.1f} s (dropout)"
            else:
                text = f"{name} repeats {y[i]:.2f} K since t = {onset:.1f} s (stuck)"
            if i < N_EKF_TCS:
                text += self._exclude(i, kind)
            else:
                text += "; TC4 only validates the estimate"
            self._declare(Detection(t, onset, name, kind, None, text))
        out = y[:N_EKF_TCS].copy()
        out[self.excluded] = np.nan
        return out

    def _exclude(self, i: int, why: str) -> str:
        if self.excluded[i]:
            self.reasons[i] = why
            return "; still left out of the estimate"
        self.excluded[i] = True
        self.reasons[i] = why
        self._recent[i] = []
        self.banks.reset()
        n_left = int((~self.excluded).sum())
        return f"; left out of the estimate ({n_left} TC{'s' if n_left != 1 else ''} left)"

    def _declare(self, d: Detection) -> None:
        log.warning("fault detected: %s", d.text)
        self.detections.append(d)
        self._pending.append(d)

    # ------------------------------------------------------------------ 2. innovation tests
    def update(self, t: float, theta_prior: Array, info: UpdateInfo | None) -> list[Detection]:
        """GLR tests after the EKF update of sample t; returns this sample's new decisions (incl. screen's)."""
        if info is not None and info.S is not None and info.gain is not None:
            n = self.model.n
            nu = self._y[:N_EKF_TCS] - self.C @ np.asarray(theta_prior, float)[:n]  # also for left-out TCs
            S = np.asarray(info.S, float)
            self._track_inflation(nu / np.sqrt(np.diag(S)))
            self._readmit(t, nu, S)
            if self.innovation_tests:
                tested = ~self.excluded & np.isfinite(nu)
                root = np.sqrt(self.inflation)  # coloured innovations count as noisier (_track_inflation)
                gain = np.asarray(info.gain, float)[:n + self.k]  # the parameters' rows too
                self.banks.update(self._j, self._C_x, nu, S * np.outer(root, root), gain, tested)
                self._decide(t)
        out, self._pending = self._pending, []
        return out

    def _track_inflation(self, z: Array) -> None:
        """kappa >= 1: how much the innovations' slow part exceeds white noise, from the past.

        For white normalised innovations the mean of a block of N samples has variance 1 / N; model
        errors (the averaged model of an oscillating specimen, eq. 11; the constant c_p) make them
        coloured, and the GLR's lambda then overstates the evidence by about
        kappa = N mean(block means^2) (a bias counts too).  kappa is measured per TC over
        ``inflation_history_s`` of blocks that end ``inflation_lag_s`` before now (a fault under test
        inflates its own yardstick only after that), and the GLR takes the innovation covariance
        as S_ij sqrt(kappa_i kappa_j): a TC whose innovations are coloured weighs less.
        """
        s = self.settings
        self._block.append(np.where(np.isfinite(z), z, np.nan))
        n = self._n(s.block_s)
        if len(self._block) < n:
            return
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a TC without a reading in the whole block: NaN
            self._block_means.append(np.nanmean(np.array(self._block), axis=0))
        self._block = []
        lag = int(round(s.inflation_lag_s / s.block_s))
        keep = lag + int(round(s.inflation_history_s / s.block_s))
        self._block_means = self._block_means[-keep:]
        past = np.array(self._block_means[:-lag]) if len(self._block_means) > lag else np.zeros((0, N_EKF_TCS))
        if len(past) * s.block_s >= s.warm_up_s - s.inflation_lag_s:
            self._ready = True
        if len(past):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # a TC without readings in the history
                var = np.nanmean(past**2, axis=0)
            self.inflation = np.maximum(1.0, np.where(np.isfinite(var), n * var, 1.0))

    def _readmit(self, t: float, nu: Array, S: Array) -> None:
        """A left-out TC is used again when, for ``readmit_s``, it gave a reading at every sample, never the
        same one twice in a row for ``flat_s``, and the mean of its normalised innovations (against the
        estimate made without it) stayed below ``readmit_z`` (after a dropout or a stuck reading: within what
        its own bias and the estimate's uncertainty explain) or ``readmit_z_biased`` (after an offset or a
        drift: within the estimate's uncertainty)."""
        s = self.settings
        z = nu / np.sqrt(np.diag(S))
        n = self._n(s.readmit_s)
        for i in np.flatnonzero(self.excluded):
            recent = self._recent[i]
            if not np.isfinite(z[i]) or self._flat[i] + 1 >= self._n(s.flat_s):
                recent.clear()
                continue
            recent.append(float(z[i]))
            del recent[:-n]
            limit = s.readmit_z_biased if self.reasons[i] in ("offset", "drift") else s.readmit_z
            if len(recent) == n and abs(float(np.mean(recent))) < limit:
                self.excluded[i] = False
                self._reported[i] = ""
                self.banks.reset()
                self._declare(Detection(t, t, TC_NAMES[i], "readmitted", None,
                                        f"{TC_NAMES[i]} agrees with the estimate again for {s.readmit_s:g} s "
                                        f"(was: {self.reasons[i]}); used again"))

    def _plausible(self, size: Array) -> NDArray[np.bool_]:
        """Which fits (banks, H) are physically possible: a group between -slack and 1 + slack of its nominal
        power after the loss, the nuisances within their ranges; offsets and drifts of any size.  Hypotheses
        that cannot apply now (about a TC left out, a group taken as failed) are not."""
        s = self.settings
        ok = np.ones(size.shape, bool)
        for h, (kind, c) in enumerate(zip(self.kinds, self.columns, strict=True)):
            if kind == "lamp":
                after = self.lamp_gains[c] - size[:, h]
                ok[:, h] = (after >= -s.gain_slack) & (after <= 1.0 + s.gain_slack) & (self.lamp_gains[c] > 0)
            elif kind in ("common", "capacity"):
                lo, hi = s.common_range if kind == "common" else s.capacity_range
                ok[:, h] = (size[:, h] >= lo) & (size[:, h] <= hi)
            else:
                ok[:, h] = not self.excluded[c]
        return ok

    def _decide(self, t: float) -> None:
        """Declare the most likely plausible fault of a mature bank when it is likely enough, beats every
        other plausible hypothesis (any onset, young banks too) by the margin and matters (module docstring)."""
        s = self.settings
        if not self._ready:
            return
        tab = self.banks.table()
        if tab is None:
            return
        llr = np.where(self._plausible(tab.size), tab.llr, 0.0)
        eligible = np.where((tab.ages >= self._n(s.min_age_s))[:, None], llr, 0.0)
        eligible[:, [h for h, kind in enumerate(self.kinds) if kind in NUISANCES]] = 0.0
        if not np.any(eligible >= s.llr_threshold):
            return
        k, h = np.unravel_index(int(np.argmax(eligible)), eligible.shape)
        best = tab.candidate(int(k), int(h), llr)
        if best.llr - best.runner_up_llr < s.llr_margin or not self._relevant(best):
            return
        self._act(t, best)

    def _relevant(self, c: Candidate) -> bool:
        s = self.settings
        kind = self.kinds[c.hypothesis]
        if kind == "offset":
            return abs(c.size) >= s.min_offset
        if kind == "drift":
            return abs(c.size) >= s.min_drift
        i = self.columns[c.hypothesis]
        return c.size >= s.min_power_loss or (c.size <= -s.min_power_loss and self.lamp_gains[i] < 1.0)

    def _act(self, t: float, c: Candidate) -> None:
        s = self.settings
        kind, target = self.kinds[c.hypothesis], self.targets[c.hypothesis]
        onset = c.onset * self.t_s
        k = float(self.inflation.max())
        how = f"GLR {c.llr:.0f}, next {self.targets[c.runner_up]} {c.runner_up_llr:.0f}" + (
            f", innovations up to x{k:.1f} white" if k > 1.05 else "")
        if kind in ("offset", "drift"):
            i = TC_NAMES.index(target)
            unit = "K" if kind == "offset" else "K/s"
            text = (f"{target} reads {'high' if c.size > 0 else 'low'}: {kind} {c.size:+.2f} {unit} "
                    f"(+/- {c.sigma:.2f}) since t = {onset:.1f} s ({how})" + self._exclude(i, kind))
            self._declare(Detection(t, onset, target, kind, c.size, text))
            return
        i = self.columns[c.hypothesis]
        before = float(self.lamp_gains[i])
        kept = float(np.clip(before - c.size, 0.0, 1.0))
        if kept < s.failed_below:
            kept, what = 0.0, "failed"
        elif kept > 1.0 - s.min_power_loss:
            kept, what = 1.0, "restored"
        else:
            what = "derate"
        self.lamp_gains[i] = kept
        self.banks.reset()
        lost = "missing" if c.size > 0 else "more than believed"
        watts = abs(c.size) * float(self._u[i]) * self._rated[i]  # electric power the loss stands for now
        text = (f"lamp group {target} {'failed' if what == 'failed' else what}: {abs(c.size):.0%} of its "
                f"nominal power {lost} (+/- {c.sigma:.0%}, {watts / 1000:.1f} kW at the power commanded now) "
                f"since t = {onset:.1f} s, now taken as {kept:.0%} ({how})")
        self._declare(Detection(t, onset, target, what, kept, text))

    # ------------------------------------------------------------------ 3. prediction
    def predict(self, u: Array, theta: Array, theta_next: Array, parameter_jacobian: Array | None = None) -> None:
        """After the EKF's prediction with the commanded powers u (m,): theta the updated estimate,
        theta_next the prediction; ``parameter_jacobian`` dF/dp (n, k) of that prediction (a calibrating
        estimator; zeros when not given)."""
        n, k = self.model.n, self.k
        self._u = np.asarray(u, float).copy()
        th = np.asarray(theta, float)[:n]
        if not self._phi_ready or self._j % self._jac_every == 0:
            self._Phi_x[:n, :n] = self.model.jac_theta(th, u)
            self._phi_ready = True
        if k:
            self._Phi_x[:n, n:] = 0.0 if parameter_jacobian is None else parameter_jacobian
        increment = np.zeros(n + k)  # the capacity hypothesis' b; p is a random walk: no increment
        increment[:n] = np.asarray(theta_next, float)[:n] - th
        self.banks.predict(self._Phi_x, self._Gamma_x, u, increment)
