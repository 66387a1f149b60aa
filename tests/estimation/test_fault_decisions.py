"""The fault detector's innovation side, sample by sample, on a linear furnace whose truth is known.

:mod:`test_fault_detection` checks the GLR sums against Willsky & Jones's exact oracle and the reading tests;
this file checks what :class:`~twin.estimation.fault_detection.FaultDetector` makes of them: which fault it
declares, when, with what size and words, what it leaves out and re-admits, how it measures coloured
innovations, and that it declares nothing on white ones.

The oracle is a linear plant written out here (4 states, 2 lamp groups, TC1..TC3 for the filter and TC4 for
validation), with process and reading noise, and a Kalman filter with its own Riccati recursion that is
*matched* to it: without a fault its normalised innovations are white N(0, 1), so any declaration is a false
alarm; a fault is injected in the plant or the readings, never told to the detector.  The detector sees the
filter as the twin's loop shows it the EKF (``twin/runs/loop.py``): readings through ``screen``, the
innovation covariance and gain through ``update``, the commanded powers through ``predict``; after a lamp
decision the filter is fed the power the detector believes the groups deliver (``lamp_gains``).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from twin.estimation.ekf import UpdateInfo
from twin.estimation.fault_detection import FaultDetector
from twin.estimation.fault_settings import DetectionSettings

T_S = 0.1
A = np.array([[0.96, 0.02, 0.0, 0.01],
              [0.02, 0.95, 0.02, 0.0],
              [0.0, 0.02, 0.96, 0.01],
              [0.01, 0.0, 0.02, 0.95]])
GAMMA = np.array([[4.0, 0.5], [2.5, 1.0], [0.5, 2.0], [1.0, 4.0]])  # K per sample at full power of each group
C3 = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.5, 0.5, 0.0], [0.0, 0.0, 0.0, 1.0]])  # TC1..TC3
C4 = np.array([0.25, 0.25, 0.25, 0.25])  # TC4 (validation only)
Q = np.eye(4) * 0.02  # K^2 per sample
R = 0.25  # K^2 (0.5 K reading noise)


class LinearModel:
    """What the detector needs of the twin's discrete model: n, fe.C, jac_theta, jac_u (here exact)."""

    def __init__(self, A: np.ndarray = A, Gamma: np.ndarray = GAMMA) -> None:
        self.n = A.shape[0]
        self.A, self.Gamma = A, Gamma
        self.fe = SimpleNamespace(C=lambda positions: C3.copy())
        self.jac_theta_calls = 0

    def jac_theta(self, theta, u):
        self.jac_theta_calls += 1
        return self.A

    def jac_u(self, theta, u):
        return self.Gamma


def furnace_cfg(groups: tuple[str, ...] = ("G1", "G2")) -> SimpleNamespace:
    """The parts of a FurnaceConfig the detector reads: t_s, the groups' names, the lamps per group, TC places."""
    return SimpleNamespace(
        sampling=SimpleNamespace(t_s=T_S),
        lamps=SimpleNamespace(groups=tuple(SimpleNamespace(name=g) for g in groups), rated_power=2000.0),
        group_matrix=np.array([[1, 0], [1, 0], [0, 1]]),  # G1 has two lamps, G2 one
        tc_positions=lambda: [(0.1, 0.1), (0.2, 0.1), (0.3, 0.1), (0.2, 0.2)],
    )


def commanded(t: float) -> np.ndarray:
    """Two groups with different time courses, so that their losses have different signatures."""
    return np.array([0.5 + 0.3 * np.sin(2 * np.pi * t / 7.0), 0.6 + 0.25 * np.sin(2 * np.pi * t / 13.0 + 1.0)])


class Rig:
    """Plant + matched Kalman filter + detector, advanced one sample at a time (module docstring).

    ``reading_fault(t, y4) -> y4`` alters the readings, ``delivered(t) -> (2,)`` is the fraction of the
    commanded power each group delivers (1 without a fault), ``status(t) -> 4 str`` the readings' status.
    """

    def __init__(self, seed: int = 0, settings: DetectionSettings | None = None, *, model: LinearModel | None = None,
                 command=commanded, **kw) -> None:
        self.rng = np.random.default_rng(seed)
        self.model = model or LinearModel()
        self.gamma, self.command = self.model.Gamma, command  # plant and model alike
        self.det = FaultDetector(furnace_cfg(), self.model, settings, **kw)
        self.x = np.linalg.solve(np.eye(4) - A, self.gamma @ command(0.0))  # the plant at its steady state
        self.xh, self.P = self.x.copy(), np.eye(4) * 0.5
        self.j = 0
        self.found: list = []
        self.z: list[np.ndarray] = []  # normalised innovations of TC1..3 (against the prior)

    @property
    def t(self) -> float:
        return round(self.j * T_S, 10)

    def step(self, reading_fault=None, delivered=None, status=None) -> list:
        t, det = self.t, self.det
        y4 = np.concatenate([C3 @ self.x, [C4 @ self.x]]) + self.rng.normal(0.0, np.sqrt(R), 4)
        if reading_fault is not None:
            y4 = reading_fault(t, y4)
        st = status(t) if status is not None else ("good",) * 4
        y = det.screen(t, y4, st)
        used = np.isfinite(y)
        S = C3 @ self.P @ C3.T + R * np.eye(3)  # of all three readings, as the EKF reports it
        L = np.zeros((4, 3))
        if used.any():
            Cu = C3[used]
            L[:, used] = self.P @ Cu.T @ np.linalg.inv(S[np.ix_(used, used)])
        nu = y - C3 @ self.xh
        self.z.append((y4[:3] - C3 @ self.xh) / np.sqrt(np.diag(S)))
        info = UpdateInfo(innovation=nu, normalized=np.abs(nu) / np.sqrt(np.diag(S)), used=used, S=S, gain=L)
        prior = self.xh.copy()
        self.xh = self.xh + L @ np.where(used, nu, 0.0)
        self.P = (np.eye(4) - L @ C3) @ self.P
        new = det.update(t, prior, info)
        self.found += new
        u = self.command(t)
        theta = self.xh.copy()
        self.xh = A @ self.xh + self.gamma @ (det.lamp_gains * u)  # the power the detector believes is delivered
        self.P = A @ self.P @ A.T + Q
        det.predict(u, theta, self.xh)
        g = delivered(t) if delivered is not None else np.ones(2)
        self.x = A @ self.x + self.gamma @ (g * u) + self.rng.multivariate_normal(np.zeros(4), Q)
        self.j += 1
        return new

    def run_until(self, t_end: float, **kw) -> list:
        new = []
        while self.t < t_end - 1e-9:
            new += self.step(**kw)
        return new


def offset_on(i: int, size: float, t0: float, t1: float = np.inf):
    def fault(t, y4):
        if t0 <= t < t1:
            y4 = y4.copy()
            y4[i] += size
        return y4
    return fault


# ----------------------------------------------------------------------------------------- no fault
@pytest.mark.parametrize("seed", [0, 1])
def test_white_innovations_raise_no_alarm_and_no_inflation(seed) -> None:
    """120 s of a matched filter without a fault: nothing declared, kappa near 1 (block means of 10 white
    samples have variance 1/10, so 10 mean(block mean^2) averages 1 over 60 blocks; a chi-square bound at
    60 degrees of freedom, 99.9 %: 1.66), every TC in use, every group at full power."""
    rig = Rig(seed)
    found = rig.run_until(120.0)
    assert found == []
    assert rig.det.inflation.max() < 1.66 and rig.det.inflation.min() >= 1.0
    assert not rig.det.excluded.any() and rig.det.lamp_gains.tolist() == [1.0, 1.0]
    z = np.array(rig.z)
    assert abs(z.mean()) < 0.1 and 0.85 < z.std() < 1.15  # the rig's own check: the filter is matched


# ----------------------------------------------------------------------------------------- sensor faults
@pytest.mark.parametrize(("size", "word"), [(6.0, "high"), (-6.0, "low")])
def test_an_offset_on_tc2_is_declared_with_its_size_onset_and_words_and_tc2_left_out(size, word) -> None:
    rig = Rig(seed=2)
    assert rig.run_until(30.0, reading_fault=offset_on(1, size, 30.0)) == []
    found = rig.run_until(35.0, reading_fault=offset_on(1, size, 30.0))
    (d,) = found
    assert (d.target, d.kind) == ("TC2", "offset")
    assert d.onset == pytest.approx(30.0)  # a bank starts every second: the onset's one is the best fit
    assert 30.5 <= d.t <= 31.5  # judged after min_age_s, declared within a second of it
    assert d.value == pytest.approx(size, abs=0.6)  # sigma of the fit ~0.1 K here; the filter's own noise
    assert d.text.startswith(f"TC2 reads {word}: offset {d.value:+.2f} K (+/- 0.")
    assert "since t = 30.0 s (GLR " in d.text and ", next TC2 " in d.text  # the runner-up: TC2's drift
    assert d.text.endswith("left out of the estimate (2 TCs left)")
    assert rig.det.excluded.tolist() == [False, True, False] and rig.det.reasons[1] == "offset"
    assert rig.det.lamp_gains.tolist() == [1.0, 1.0]


def test_an_offset_below_min_offset_is_left_to_the_estimate() -> None:
    """2 K is found by the GLR (lambda in the hundreds) but under ``min_offset`` (3 K): not declared; with the
    bar at 1.5 K the same run declares it."""
    rig = Rig(seed=3)
    assert rig.run_until(50.0, reading_fault=offset_on(0, 2.0, 30.0)) == []
    tab = rig.det.banks.table()
    assert tab.llr.max() > rig.det.settings.llr_threshold
    rig = Rig(seed=3, settings=DetectionSettings(min_offset=1.5))
    found = rig.run_until(50.0, reading_fault=offset_on(0, 2.0, 30.0))
    assert [(d.target, d.kind) for d in found] == [("TC1", "offset")]
    assert found[0].value == pytest.approx(2.0, abs=0.5)


def test_a_drift_on_tc1_is_declared_with_its_rate() -> None:
    """2 K/s from t = 30 s.  The rate is a fit over the first two seconds or so of the ramp, from banks a second
    apart, while the drift already colours the innovations (kappa rises): within 30 % (seeds 4-7 of this rig:
    1.47-2.37 K/s, onset 29-30 s)."""
    def drift(t, y4):
        y4 = y4.copy()
        if t >= 30.0:
            y4[0] += 2.0 * (t - 30.0)
        return y4
    rig = Rig(seed=4)
    found = rig.run_until(40.0, reading_fault=drift)
    (d,) = found
    assert (d.target, d.kind) == ("TC1", "drift")
    assert d.value == pytest.approx(2.0, rel=0.3)
    assert d.onset == pytest.approx(30.0, abs=1.0) and d.t < 33.0
    assert f"TC1 reads high: drift {d.value:+.2f} K/s" in d.text
    assert rig.det.excluded.tolist() == [True, False, False] and rig.det.reasons[0] == "drift"


def test_no_innovation_test_decides_before_the_warm_up() -> None:
    """An offset from t = 12 s: the detector needs warm_up_s = 20 s of history for its inflation before the
    GLR may decide (the bank of t = 12 s is still alive then: window_s = 20 s)."""
    rig = Rig(seed=5)
    early = rig.run_until(19.85, reading_fault=offset_on(2, 8.0, 12.0))
    assert early == []
    found = rig.run_until(24.0, reading_fault=offset_on(2, 8.0, 12.0))
    assert [(d.target, d.kind) for d in found] == [("TC3", "offset")] and found[0].t >= 19.9


def test_innovation_tests_switched_off_declare_nothing_and_back_on_they_restart() -> None:
    rig = Rig(seed=6)
    rig.det.set_innovation_tests(False)
    assert rig.run_until(60.0, reading_fault=offset_on(1, 8.0, 30.0)) == []
    assert rig.det.banks.n_banks == 0  # not even followed
    assert rig.det.inflation[1] > 10.0  # the inflation is followed all along (the offset colours TC2)
    rig.det.set_innovation_tests(True)
    rig.det.inflation[:] = 1.0  # as if the history were clean, to see the restart alone
    found = rig.run_until(70.0, reading_fault=offset_on(1, 8.0, 30.0))
    assert rig.det.banks.n_banks > 0
    # the filter has absorbed most of the offset by now, what is left is a step in the innovations of the TC's
    # share: either found again from the restart or nothing, never another target
    assert all(d.target == "TC2" for d in found)


# ----------------------------------------------------------------------------------------- lamp faults
def test_a_failed_group_is_declared_failed_and_the_filter_fed_without_it() -> None:
    rig = Rig(seed=7)
    lost = lambda t: np.array([0.0, 1.0]) if t >= 30.0 else np.ones(2)  # noqa: E731
    found = rig.run_until(40.0, delivered=lost)
    (d,) = found
    assert (d.target, d.kind, d.value) == ("G1", "failed", 0.0)
    assert d.onset == pytest.approx(30.0, abs=1.0) and d.t < 33.0
    assert rig.det.lamp_gains.tolist() == [0.0, 1.0]
    assert d.text.startswith("lamp group G1 failed: ")
    assert "of its nominal power missing" in d.text and "now taken as 0%" in d.text
    # the electric power the loss stands for: the fitted fraction x the commanded power x G1's two lamps x 2 kW
    size = float(d.text.split(": ")[1].split("%")[0]) / 100
    kw = float(d.text.split("+/- ")[1].split(", ")[1].split(" kW")[0])
    u0 = commanded(round(d.t - T_S, 10))[0]  # the powers commanded last, before the decision's sample
    assert kw == pytest.approx(size * u0 * 2 * 2000.0 / 1000, abs=0.06)
    # fed the power it delivers, the filter is matched again: no further decision for 30 s
    assert rig.run_until(70.0, delivered=lost) == []


def test_a_halved_group_is_derated_to_what_it_keeps_and_restored_when_it_comes_back() -> None:
    rig = Rig(seed=8)
    half = lambda t: np.array([1.0, 0.5]) if 30.0 <= t < 80.0 else np.ones(2)  # noqa: E731
    found = rig.run_until(45.0, delivered=half)
    (d,) = found
    assert (d.target, d.kind) == ("G2", "derate")
    assert d.value == pytest.approx(0.5, abs=0.08) and rig.det.lamp_gains[1] == d.value
    assert "lamp group G2 derate: " in d.text and f"now taken as {d.value:.0%}" in d.text
    size = float(d.text.split(": ")[1].split("%")[0]) / 100
    kw = float(d.text.split("+/- ")[1].split(", ")[1].split(" kW")[0])
    assert kw == pytest.approx(size * commanded(round(d.t - T_S, 10))[1] * 1 * 2000.0 / 1000, abs=0.06)  # G2: 1 lamp
    assert rig.run_until(80.0, delivered=half) == []
    back = rig.run_until(95.0, delivered=half)
    (r,) = back
    assert (r.target, r.kind, r.value) == ("G2", "restored", 1.0)
    assert "more than believed" in r.text and rig.det.lamp_gains.tolist() == [1.0, 1.0]


def test_more_power_than_nominal_is_not_a_fault_of_a_healthy_group() -> None:
    """A group at full belief delivering 20 % more (a gain the model misses, not a lost lamp) is never a
    'restored' or 'derate' decision: only a group already derated can come back (``_relevant``)."""
    rig = Rig(seed=9)
    more = lambda t: np.array([1.0, 1.2]) if t >= 30.0 else np.ones(2)  # noqa: E731
    found = rig.run_until(60.0, delivered=more)
    assert [d for d in found if d.target in ("G1", "G2")] == []
    assert rig.det.lamp_gains.tolist() == [1.0, 1.0]
    # the premise: the GLR does see G2's extra power, likely enough and large enough to be declared otherwise
    tab = rig.det.banks.table()
    g2 = rig.det.targets.index("G2")
    k = int(np.argmax(tab.llr[:, g2]))
    assert tab.llr[k, g2] > rig.det.settings.llr_threshold and tab.size[k, g2] < -rig.det.settings.min_power_loss


def test_a_loss_no_data_can_attribute_to_one_group_is_not_declared() -> None:
    """Two groups with the same input column and the same commanded power: a loss of either fits equally well
    (lambda the same to rounding), so the best does not beat the runner-up by ``llr_margin``."""
    gamma = np.array([[2.0, 2.0], [1.5, 1.5], [1.0, 1.0], [2.0, 2.0]])
    rig = Rig(seed=10, model=LinearModel(Gamma=gamma), command=lambda t: np.array([0.5, 0.5]))
    found = rig.run_until(50.0, delivered=lambda t: np.array([0.4, 1.0]) if t >= 30.0 else np.ones(2))
    assert found == []
    tab = rig.det.banks.table()
    g1, g2 = rig.det.kinds.index("lamp"), rig.det.kinds.index("lamp") + 1
    assert tab.llr[:, g1].max() > rig.det.settings.llr_threshold
    assert tab.llr[:, g1] == pytest.approx(tab.llr[:, g2], rel=1e-6)


# ----------------------------------------------------------------------------------------- plausibility
def test_plausible_fits_follow_the_groups_belief_and_the_nuisances_ranges() -> None:
    det = FaultDetector(furnace_cfg(), LinearModel())
    kinds = det.kinds
    assert kinds == ("offset",) * 3 + ("drift",) * 3 + ("lamp", "lamp", "common", "capacity")
    assert det.targets == ("TC1", "TC2", "TC3") * 2 + ("G1", "G2", "all groups", "heat capacity")
    det.lamp_gains = np.array([1.0, 0.5])
    det.excluded = np.array([False, True, False])
    s = det.settings  # gain_slack 0.25, common (-0.5, 0.5), capacity (-0.5, 1.0)
    size = np.array([
        # TC1..3 offsets, drifts, G1 loss, G2 loss, common, capacity
        [9.0, 9.0, -9.0, 1.0, 1.0, 1.0, 1.25, -0.75, 0.5, 1.0],  # every bound met exactly
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.26, -0.76, 0.51, 1.01],  # every bound just missed
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.25, 0.75, -0.5, -0.5],  # the other ends, met
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.26, 0.76, -0.51, -0.51],  # the other ends, missed
    ])
    ok = det._plausible(size)
    assert s.gain_slack == 0.25
    assert ok.tolist() == [
        [True, False, True, True, False, True, True, True, True, True],
        [True, False, True, True, False, True, False, False, False, False],
        [True, False, True, True, False, True, True, True, True, True],
        [True, False, True, True, False, True, False, False, False, False],
    ]
    det.lamp_gains = np.array([0.0, 0.5])  # G1 taken as failed: nothing more about it is plausible
    assert not det._plausible(np.zeros((1, 10)))[0, 6]


# ----------------------------------------------------------------------------------------- inflation
def _feed_z(det: FaultDetector, z_rows) -> None:
    """Innovations with prescribed normalised values, S = I: readings z + r_j and theta_prior = r_j 1, so that
    nu = y - C3 theta_prior = z (each row of C3 sums to 1); the ramp r_j = 1e-3 j keeps a reading from being
    "the same value" as the last (the stuck test)."""
    det.set_innovation_tests(False)
    info = UpdateInfo(innovation=np.zeros(3), normalized=np.zeros(3), used=np.ones(3, bool), S=np.eye(3),
                      gain=np.zeros((4, 3)))
    j0 = det._j + 1
    for k, z in enumerate(z_rows):
        j = j0 + k
        r = 1e-3 * j
        det.screen(j * T_S, np.concatenate([z, [0.0]]) + r, ("good",) * 4)
        det.update(j * T_S, np.full(4, r), info)


def test_inflation_is_the_block_means_square_times_the_block_length_lagged_and_finite() -> None:
    """z = 0.5 on TC1, 0 on TC2, +-1 alternating on TC3 (white-ish: block means 0): kappa_1 = 10 x 0.25 = 2.5
    once a block older than the lag (5 s) exists, kappa_2 = kappa_3 = 1 (floored); after z returns to 0 at
    10 s, kappa_1 falls back to 1 when the 0.5-blocks leave the 60 s history."""
    det = FaultDetector(furnace_cfg(), LinearModel())
    n = 10  # block_s / t_s
    rows = [np.array([0.5 if j < 100 else 0.0, 0.0, (-1.0) ** j]) for j in range(900)]  # 10 blocks of 0.5
    _feed_z(det, rows[:59])  # 5 blocks + 9 samples: every finished block is within the lag
    assert det.inflation.tolist() == [1.0, 1.0, 1.0] and not det._ready
    _feed_z(det, rows[59:60])  # the 6th block ends: the first one leaves the lag
    assert det.inflation == pytest.approx([n * 0.25, 1.0, 1.0])
    _feed_z(det, rows[60:200])
    # 20 blocks: the past is blocks 0-14, 10 of them at 0.5: the mean square over all of them
    assert det.inflation[0] == pytest.approx(n * 0.25 * 10 / 15) and det._ready  # 15 s of past >= warm_up - lag
    _feed_z(det, rows[200:840])  # at 84 s: the past blocks are those ending 24..79 s, all zero on TC1
    assert det.inflation[0] == pytest.approx(n * 0.25 * 0 + 1.0)
    # the lag and the history exactly: z = 3 in blocks 0-9, kappa_1 = 10 x 9 x k / 60 with k of them in the
    # 60-block history that ends 5 blocks back
    det2 = FaultDetector(furnace_cfg(), LinearModel())
    rows3 = [np.array([3.0 if j < 100 else 0.0, 0.0, 0.0]) for j in range(740)]
    _feed_z(det2, rows3[:700])  # 70 blocks; history = blocks 5..64: k = 5
    assert det2.inflation[0] == pytest.approx(n * 9 * 5 / 60)
    _feed_z(det2, rows3[700:740])  # 74 blocks; history = blocks 9..68: k = 1
    assert det2.inflation[0] == pytest.approx(n * 9 * 1 / 60)


# ----------------------------------------------------------------------------------------- readmission
def test_a_tc_whose_offset_ends_is_used_again_within_readmit_s() -> None:
    rig = Rig(seed=11)
    fault = offset_on(1, 6.0, 30.0, 60.0)
    rig.run_until(60.0, reading_fault=fault)
    assert [(d.target, d.kind) for d in rig.found] == [("TC2", "offset")] and rig.det.excluded[1]
    back = rig.run_until(66.0, reading_fault=fault)
    (d,) = back
    assert (d.target, d.kind) == ("TC2", "readmitted")
    # the mean of the last 30 normalised innovations falls below readmit_z_biased (1) once at most a few of
    # them carry the offset (z ~ 6 K / 0.55 K): between 2.5 and 3 s after it ended
    assert 62.5 <= d.t <= 63.0
    assert d.text == "TC2 agrees with the estimate again for 3 s (was: offset); used again"
    assert not rig.det.excluded.any()


def _after_dropout(seed: int, bias: float, settings: DetectionSettings | None = None) -> Rig:
    """TC3 drops out at 30 s for 5 s, then reads again with ``bias`` K (a TC's own deviation the estimate had
    absorbed while it used it: docs/faults.md, ``readmit_z``)."""
    rig = Rig(seed, settings)
    def fault(t, y4):
        y4 = y4.copy()
        if 30.0 <= t < 35.0:
            y4[2] = np.nan
        elif t >= 35.0:
            y4[2] += bias
        return y4
    status = lambda t: ("good", "good", "missing" if 30.0 <= t < 35.0 else "good", "good")  # noqa: E731
    rig.run_until(45.0, reading_fault=fault, status=status)
    return rig


def test_a_tc_back_from_a_dropout_with_a_moderate_bias_is_used_again_within_readmit_z_only() -> None:
    """The returning reading is biased by about 1.7 of its innovation's sigma: within ``readmit_z`` (3), which
    applies after a dropout, but not within 1 (``readmit_z_biased``, the bar after an offset or a drift)."""
    rig = _after_dropout(12, bias=1.6)
    kinds = [(d.target, d.kind) for d in rig.found]
    assert kinds == [("TC3", "dropout"), ("TC3", "readmitted")]
    readmit = rig.found[1]
    assert readmit.t == pytest.approx(37.9)  # 30 readings (3 s) from the return at 35.0 s
    assert "(was: dropout)" in readmit.text
    z3 = np.array(rig.z)[350:380, 2]
    assert 1.3 < z3.mean() < 2.7  # the premise: between the two limits
    rig = _after_dropout(12, bias=1.6, settings=DetectionSettings(readmit_z=1.0))
    assert [(d.target, d.kind) for d in rig.found] == [("TC3", "dropout")]


def test_a_left_out_tc_that_reads_a_frozen_value_is_not_used_again() -> None:
    """Constant powers: the plant sits at its steady state and a frozen reading stays within the noise of the
    estimate (|mean z| well below ``readmit_z``), so only the repeated value keeps TC1 out."""
    rig = Rig(seed=13, command=lambda t: np.array([0.5, 0.6]))
    frozen = {}
    def fault(t, y4):
        y4 = y4.copy()
        if t >= 30.0:
            y4[0] = frozen.setdefault(0, y4[0])
        return y4
    rig.run_until(60.0, reading_fault=fault)
    assert [(d.target, d.kind) for d in rig.found] == [("TC1", "stuck")]
    assert rig.det.excluded.tolist() == [True, False, False]
    assert abs(np.array(rig.z)[300:600, 0].mean()) < 1.5  # the premise: the value alone would pass


# ----------------------------------------------------------------------------------------- the model
def test_set_model_restarts_the_signatures_with_the_new_model() -> None:
    rig = Rig(seed=14)
    rig.run_until(25.0)
    assert rig.det.banks.n_banks > 0
    other = LinearModel(Gamma=GAMMA * 2.0)
    rig.det.set_model(other)
    assert rig.det.banks.n_banks == 0 and rig.det.model is other
    assert rig.det._Gamma_x == pytest.approx(GAMMA * 2.0)
    calls = other.jac_theta_calls
    rig.det.predict(commanded(25.0), rig.xh, rig.xh)
    assert other.jac_theta_calls == calls + 1  # Phi evaluated at once for the new model


def test_phi_is_evaluated_every_jacobian_every_s() -> None:
    model = LinearModel()
    rig = Rig(seed=15, model=model, jacobian_every_s=0.5)
    rig.run_until(10.0)
    assert model.jac_theta_calls == 20  # 100 samples, every 5th (j = 0, 5, ...)


def _calibrating_run(seed: int, loss: float = 0.6) -> list:
    """A filter that also estimates a common lamp efficiency p (x+ = A x + Gamma (g u) (1 + p), p a random walk
    of 1e-3 per sample: the joint EKF's structure, eq. 16), with the detector at ``n_parameters = 1``; G1 loses
    ``loss`` of its power from t = 30 s.  Returns the detector's decisions up to the first."""
    rng = np.random.default_rng(seed)
    det = FaultDetector(furnace_cfg(), LinearModel(), n_parameters=1)
    assert det._C_x.shape == (3, 5) and det._Gamma_x.shape == (5, 2) and not det._Gamma_x[4].any()
    x = np.linalg.solve(np.eye(4) - A, GAMMA @ commanded(0.0))
    xh, P = np.concatenate([x, [0.0]]), np.diag([0.5, 0.5, 0.5, 0.5, 1e-4])
    Qx = np.diag([0.02, 0.02, 0.02, 0.02, 1e-3])
    Cx = np.concatenate([C3, np.zeros((3, 1))], axis=1)
    found: list = []
    for j in range(400):
        t = round(j * T_S, 10)
        y4 = np.concatenate([C3 @ x, [C4 @ x]]) + rng.normal(0.0, np.sqrt(R), 4)
        y = det.screen(t, y4, ("good",) * 4)
        S = Cx @ P @ Cx.T + R * np.eye(3)
        L = P @ Cx.T @ np.linalg.inv(S)
        nu = y - Cx @ xh
        info = UpdateInfo(innovation=nu, normalized=np.abs(nu), used=np.ones(3, bool), S=S, gain=L)
        prior = xh.copy()
        xh = xh + L @ nu
        P = (np.eye(5) - L @ Cx) @ P
        found += det.update(t, prior, info)
        if found:
            return found
        u = commanded(t)
        ub = det.lamp_gains * u
        Phi = np.eye(5)
        Phi[:4, :4], Phi[:4, 4] = A, GAMMA @ ub
        theta = xh.copy()
        xh = np.concatenate([A @ xh[:4] + GAMMA @ ub * (1 + xh[4]), [xh[4]]])
        P = Phi @ P @ Phi.T + Qx
        det.predict(u, theta, xh, Phi[:4, 4:])  # dF/dp of this prediction
        g = np.array([1.0 - loss, 1.0]) if t >= 30.0 else np.ones(2)
        x = A @ x + GAMMA @ (g * u) + rng.multivariate_normal(np.zeros(4), Q)
    return found


def test_with_a_calibrating_filter_a_lost_fraction_is_sized_in_the_augmented_state() -> None:
    """A 60 % loss of G1 is derated to 40 % kept, not to more (docs/faults.md: a failed group taken as 82 %
    lost was this bug).  Seeds 16-19: kept 0.33-0.47, mean 0.40; with dF/dp left out of the signatures the same
    runs gave 0.47-0.53 and one TC1 drift."""
    kept = []
    for seed in (16, 17, 18, 19):
        (d,) = _calibrating_run(seed)
        assert (d.target, d.kind) == ("G1", "derate")
        kept.append(d.value)
    assert np.mean(kept) == pytest.approx(0.4, abs=0.04) and np.ptp(kept) < 0.2
