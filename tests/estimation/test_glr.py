"""The GLR banks (twin.estimation.glr) entry by entry against a brute-force oracle.

Oracle: a Kalman filter on a *linear* plant has gains that do not depend on the data, so its innovations
are affine in an additive fault: nu_j(f) = nu_j(0) + f sigma_j (Willsky & Jones 1976).  The signature
sigma_j of each hypothesis and onset is measured here by running the filter (written out below) again on
the plant with a unit fault of that kind planted at that onset and taking the difference of the
innovations; the sums A = sum sigma^T S^-1 nu, B = sum sigma^T S^-1 sigma are then formed directly over
the readings present and tested, and lambda = A^2 / B, f = A / B, sd(f) = 1 / sqrt(B) (module docstring).
Nothing of SignatureBanks' recursion (a - C s, s + L sigma, Phi s + b) or of its bank bookkeeping is used.

The scenario has every kind of hypothesis, a sampling time that is not 1 s, a reading that is missing at
some samples (the filter skips it) and one that the filter uses but that is not always tested, banks
started every 3 samples and dropped after 10, and is checked after every sample (the window's edges).
"""

from __future__ import annotations

import warnings
from functools import cache

import numpy as np
import pytest

from twin.estimation.glr import SignatureBanks, Table

A = np.array([[0.93, 0.04, 0.0, 0.01], [0.03, 0.9, 0.05, 0.0], [0.0, 0.04, 0.92, 0.03], [0.02, 0.0, 0.05, 0.88]])
G = np.array([[0.5, 0.1], [0.2, 0.4], [0.05, 0.6], [0.3, 0.2]])  # two "lamp groups"
C = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.6, 0.4, 0.0], [0.0, 0.0, 0.3, 0.7]])  # three "TCs"
Q, R = np.diag([0.04, 0.03, 0.05, 0.02]), np.diag([0.09, 0.16, 0.04])
T_S = 0.25
N, EVERY, WINDOW = 40, 3, 10
# the column of "common" and "capacity" is ignored (given as 1 and 2 here so that using it would show)
KINDS = ("offset", "drift", "lamp", "lamp", "common", "capacity", "offset")
COLS = (2, 0, 1, 0, 1, 2, 1)
DATA_FAULT = ("lamp", 0, 9, 0.8)  # the data: group 0 loses 80 % of its power from sample 9


def _inputs() -> tuple[np.ndarray, np.ndarray]:
    """Commanded powers and the "capacity" increments passed to predict (any fixed sequences)."""
    j = np.arange(N)
    u = np.stack([1.0 + 0.5 * np.sin(0.3 * j), 2.0 - 0.4 * np.cos(0.2 * j)], axis=1)
    rng = np.random.default_rng(3)
    return u, rng.normal(0.0, 0.5, (N, 4))


U, D = _inputs()


def _present(j: int) -> np.ndarray:
    return np.array([True, j % 5 != 3, True])  # TC 1 has no reading at j = 3, 8, 13, ...


def _tested(j: int) -> np.ndarray:
    return np.array([True, True, j % 4 != 1])  # TC 2 is used by the filter but not tested at j = 1, 5, ...


@cache
def _filter(fault: tuple[str, int, int, float] | None) -> tuple[tuple[np.ndarray, ...], ...]:
    """Per sample (nu, S, L) of a Kalman filter on the noisy linear plant with ``fault`` = (kind, column,
    onset, size); the same noise in every call, so the innovations differ by the fault's effect alone."""
    rng = np.random.default_rng(11)
    x = np.array([3.0, 1.0, -2.0, 0.5])
    xh, P = x + np.array([0.3, -0.2, 0.1, 0.0]), np.eye(4)
    out = []
    for j in range(N):
        v, w = rng.normal(0.0, 0.3, 3), rng.normal(0.0, 0.2, 4)
        y = C @ x + v
        if fault is not None:
            kind, col, onset, f = fault
            if kind == "offset" and j >= onset:
                y[col] += f
            if kind == "drift" and j >= onset:
                y[col] += f * (j - onset) * T_S
        obs = _present(j)
        y[~obs] = np.nan
        S = C @ P @ C.T + R
        Lo = P @ C[obs].T @ np.linalg.inv(S[np.ix_(obs, obs)])
        L = np.zeros((4, 3))
        L[:, obs] = Lo
        nu = y - C @ xh
        out.append((nu, S, L))
        xh = xh + Lo @ nu[obs]
        P = (np.eye(4) - Lo @ C[obs]) @ P
        delivered = G @ U[j]
        if fault is not None and j >= fault[2]:
            kind, col, _, f = fault
            if kind == "lamp":
                delivered = delivered - f * G[:, col] * U[j, col]
            if kind == "common":
                delivered = delivered - f * G @ U[j]
            if kind == "capacity":
                delivered = delivered - f * D[j]
        x = A @ x + delivered + w
        xh = A @ xh + G @ U[j]
        P = A @ P @ A.T + Q
    return tuple(out)


def _expected(J: int, onsets: list[int]) -> dict[str, np.ndarray]:
    """The table after sample J for the banks started at ``onsets``, by brute force."""
    data = _filter(DATA_FAULT)
    nominal = _filter(None)
    H = len(KINDS)
    Asum, Bsum = np.zeros((len(onsets), H)), np.zeros((len(onsets), H))
    for r, o in enumerate(onsets):
        for h, (kind, col) in enumerate(zip(KINDS, COLS, strict=True)):
            unit = _filter((kind, col, o, 1.0))
            for j in range(o, J + 1):
                use = _present(j) & _tested(j)
                sig = (unit[j][0] - nominal[j][0])[use]
                Sinv = np.linalg.inv(data[j][1][np.ix_(use, use)])
                Asum[r, h] += sig @ Sinv @ data[j][0][use]
                Bsum[r, h] += sig @ Sinv @ sig
    ok = Bsum > 1e-12
    Bsafe = np.where(ok, Bsum, 1.0)
    return {"llr": np.where(ok, Asum**2 / Bsafe, 0.0), "size": np.where(ok, Asum / Bsafe, 0.0),
            "sigma": np.where(ok, 1.0 / np.sqrt(Bsafe), np.inf), "onsets": np.array(onsets, int),
            "ages": J - np.array(onsets, int)}


def _feed(banks: SignatureBanks, j: int) -> None:
    nu, S, L = _filter(DATA_FAULT)[j]
    banks.update(j, C, nu, S, L, _tested(j))
    banks.predict(A, G, U[j], D[j])


def _new_banks() -> SignatureBanks:
    return SignatureBanks(4, 3, KINDS, COLS, onset_every=EVERY, window=WINDOW, t_s=T_S)


def _check(tab: Table | None, want: dict[str, np.ndarray]) -> None:
    assert tab is not None
    np.testing.assert_array_equal(tab.onsets, want["onsets"])
    np.testing.assert_array_equal(tab.ages, want["ages"])
    for key in ("llr", "size", "sigma"):
        got = getattr(tab, key)
        assert got.shape == want[key].shape, key
        np.testing.assert_allclose(got, want[key], rtol=1e-9, atol=1e-10, err_msg=key)


@cache
def _tables() -> tuple[Table, ...]:
    banks = _new_banks()
    tables = []
    for j in range(N):
        _feed(banks, j)
        tables.append(banks.table())
    return tuple(tables)


def test_oracle_sees_the_planted_fault() -> None:
    """The oracle itself: the data's lamp-0 fault is the most likely hypothesis of the bank at its onset."""
    want = _expected(18, [9, 12, 15, 18])
    k = 0  # the bank started at the fault's onset
    assert int(np.argmax(want["llr"][k])) == 3
    assert want["size"][k, 3] == pytest.approx(0.8, abs=3 * want["sigma"][k, 3])


@pytest.mark.parametrize("J", range(N))
def test_banks_match_the_brute_force_glr_at_every_sample(J: int) -> None:
    """lambda, size and sd of every hypothesis at every live onset, the onsets (every 3 samples, dropped
    when 10 old) and their ages, after each sample."""
    onsets = [o for o in range(0, J + 1, EVERY) if J - o < WINDOW]
    _check(_tables()[J], _expected(J, onsets))


def test_reset_forgets_every_bank_and_starts_afresh() -> None:
    banks = _new_banks()
    for j in range(17):
        _feed(banks, j)
    assert banks.n_banks == 3  # onsets 9, 12, 15
    banks.reset()
    assert banks.n_banks == 0 and banks.table() is None and banks.best(min_age=0) is None
    banks.predict(A, G, U[16], D[16])  # nothing to predict: no error, no bank
    _feed(banks, 17)  # 17 is no onset: still no bank
    assert banks.table() is None
    for J in range(18, N):
        _feed(banks, J)
        _check(banks.table(), _expected(J, [o for o in range(18, J + 1, EVERY) if J - o < WINDOW]))


def test_no_bank_before_the_first_update() -> None:
    banks = _new_banks()
    banks.predict(A, G, U[0], D[0])
    assert banks.n_banks == 0 and banks.table() is None and banks.best(min_age=0) is None


def test_a_hypothesis_without_information_carries_no_evidence() -> None:
    """B <= 1e-12 (here exactly 1e-12: one reading of variance 1e12) gives lambda = size = 0 and sd = inf;
    just above it the ratio is formed."""
    for S, B in ((1e12, 1e-12), (2.5e11, 4e-12)):
        banks = SignatureBanks(1, 1, ("offset",), (0,), onset_every=1, window=5, t_s=1.0)
        banks.update(0, np.ones((1, 1)), np.array([3e-6]), np.array([[S]]), np.zeros((1, 1)), np.array([True]))
        tab = banks.table()
        if B <= 1e-12:
            assert (tab.llr[0, 0], tab.size[0, 0], tab.sigma[0, 0]) == (0.0, 0.0, np.inf)
        else:
            A_ = 3e-6 / S
            assert tab.llr[0, 0] == pytest.approx(A_**2 / B, rel=1e-12)
            assert tab.size[0, 0] == pytest.approx(A_ / B, rel=1e-12)
            assert tab.sigma[0, 0] == pytest.approx(B**-0.5, rel=1e-12)


def test_signatures_are_formed_in_double_precision() -> None:
    """Single-precision model matrices and powers give the same banks as their exact double values: the
    powers are converted before the products (a float32 Gamma u rounds the lamp signatures to ~1e-7)."""
    tables = []
    for dtype in (np.float32, np.float64):
        banks = _new_banks()
        G32, U32 = G.astype(np.float32).astype(dtype), U.astype(np.float32).astype(dtype)
        for j in range(12):
            nu, S, L = _filter(DATA_FAULT)[j]
            banks.update(j, C, nu, S, L, _tested(j))
            banks.predict(A, G32, U32[j], D[j])
        tables.append(banks.table())
    np.testing.assert_array_equal(tables[0].llr, tables[1].llr)
    np.testing.assert_array_equal(tables[0].size, tables[1].size)


def test_the_column_layout_is_made_once_per_number_of_banks() -> None:
    """Issue 21: the hypotheses' columns over nb banks are computed once, not at every sample."""
    banks = _new_banks()
    assert banks._layout(2) is banks._layout(2)
    assert banks._layout(3) is not banks._layout(2)


def _brute_best(tab: Table, min_age: int) -> tuple[int, int] | None:
    best, where = 0.0, None
    for k in range(tab.llr.shape[0]):
        for h in range(tab.llr.shape[1]):
            if tab.ages[k] >= min_age and tab.llr[k, h] > best:
                best, where = tab.llr[k, h], (k, h)
    return where


def _brute_runner_up(llr: np.ndarray, h: int) -> tuple[int, float]:
    best, which = -np.inf, -1
    for k in range(llr.shape[0]):
        for g in range(llr.shape[1]):
            if g != h and llr[k, g] > best:
                best, which = llr[k, g], g
    return which, max(best, 0.0)


@pytest.mark.parametrize("J", [9, 20, 39])
def test_best_is_the_largest_lambda_of_a_mature_bank_with_the_runner_up_of_any_bank(J: int) -> None:
    tab = _tables()[J]
    banks = _new_banks()
    for j in range(J + 1):
        _feed(banks, j)
    # every age of a live bank as min_age (the boundary: a bank exactly min_age old is mature) and beyond
    for min_age in [0, *sorted(int(a) for a in tab.ages), int(tab.ages.max()) + 1]:
        got, where = banks.best(min_age), _brute_best(tab, min_age)
        if where is None:
            assert got is None
            continue
        k, h = where
        runner_up, runner_up_llr = _brute_runner_up(tab.llr, h)
        assert (got.hypothesis, got.onset, got.age, got.runner_up) == (h, tab.onsets[k], tab.ages[k], runner_up)
        assert (got.size, got.sigma, got.llr, got.runner_up_llr) == pytest.approx(
            (tab.size[k, h], tab.sigma[k, h], tab.llr[k, h], runner_up_llr), rel=1e-12)
    assert banks.best(int(tab.ages.max()) + 1) is None


def test_best_with_weak_evidence_and_with_none() -> None:
    """A lambda below 1 is still the best; no evidence at all (every innovation 0) is no candidate, also
    when younger banks are left out."""
    def banks_with(nus: list[float]) -> SignatureBanks:
        b = SignatureBanks(1, 1, ("offset", "drift"), (0, 0), onset_every=2, window=50, t_s=0.5)
        for j, nu in enumerate(nus):
            b.update(j, np.ones((1, 1)), np.array([nu]), np.eye(1), np.zeros((1, 1)), np.array([True]))
        return b

    weak = banks_with([0.3, 0.3, 0.3])  # banks at 0 and 2: offset A = 0.9, B = 3; drift A = 0.45, B = 1.25
    c = weak.best(min_age=1)
    assert (c.hypothesis, c.onset, c.age, c.runner_up) == (0, 0, 2, 1)
    assert (c.llr, c.size, c.sigma) == pytest.approx((0.27, 0.3, 3**-0.5), rel=1e-12)
    # the runner-up is the drift's largest lambda at any onset: 0.45^2 / 1.25 at onset 0 (0 at onset 2)
    assert c.runner_up_llr == pytest.approx(0.45**2 / 1.25, rel=1e-12)
    none = banks_with([0.0, 0.0, 0.0, 0.0])
    assert none.best(min_age=0) is None
    assert none.best(min_age=2) is None  # the bank at 2 is too young, the one at 0 has lambda 0


def test_candidate_of_a_table() -> None:
    """Bank k's hypothesis h with the sizes of the table and the lambda of ``competitors``; the runner-up
    is the best other hypothesis at any onset (-1 and 0 when there is none), ``competitors`` untouched."""
    llr = np.array([[1.0, 5.0, 2.0], [7.0, 0.5, 3.0]])
    tab = Table(llr, np.arange(6.0).reshape(2, 3), np.arange(6.0, 12.0).reshape(2, 3), np.array([4, 8]),
                np.array([6, 2]))
    competitors = np.array([[1.0, 4.0, 0.2], [0.1, 9.0, 0.3]])  # e.g. the plausible hypotheses' lambda
    before = competitors.copy()
    c = tab.candidate(0, 1, competitors)
    np.testing.assert_array_equal(competitors, before)
    assert (c.hypothesis, c.onset, c.age, c.size, c.sigma, c.llr) == (1, 4, 6, 1.0, 7.0, 4.0)
    assert (c.runner_up, c.runner_up_llr) == (0, 1.0)
    c = tab.candidate(1, 0, competitors)
    assert (c.hypothesis, c.onset, c.age, c.size, c.sigma, c.llr, c.runner_up) == (0, 8, 2, 3.0, 9.0, 0.1, 1)
    assert c.runner_up_llr == 9.0
    c = tab.candidate(1, 1, np.array([[0.0, 4.0, 0.2], [0.1, 0.0, 0.3]]))
    assert (c.runner_up, c.runner_up_llr) == (2, 0.3)  # below 1: kept as it is
    # one hypothesis: no runner-up
    one = Table(np.array([[2.0]]), np.array([[1.5]]), np.array([[0.5]]), np.array([3]), np.array([1]))
    c = one.candidate(0, 0, one.llr)
    assert (c.hypothesis, c.onset, c.age, c.size, c.sigma, c.llr, c.runner_up, c.runner_up_llr) == (
        0, 3, 1, 1.5, 0.5, 2.0, -1, 0.0)


def test_without_an_increment_the_capacity_signature_is_only_propagated() -> None:
    """``increment`` is optional: a sample without it adds b = 0 to the capacity hypothesis (its signature
    is carried on by Phi), the same as a zero increment, not an unknown one."""
    tables = []
    for missing in (None, np.zeros(2)):
        banks = SignatureBanks(2, 1, ("capacity", "offset"), (0, 0), onset_every=10, window=10, t_s=1.0)
        C1, S1, L1, Phi = np.array([[1.0, 0.5]]), np.eye(1), np.array([[0.3], [0.1]]), np.array([[0.9, 0.1], [0, 0.8]])
        for j, inc in enumerate((np.array([1.0, -0.5]), missing, np.array([0.2, 0.4]))):
            banks.update(j, C1, np.array([0.7 - 0.2 * j]), S1, L1, np.array([True]))
            banks.predict(Phi, np.zeros((2, 1)), np.zeros(1), inc)
        banks.update(3, C1, np.array([0.1]), S1, L1, np.array([True]))
        tables.append(banks.table())
    np.testing.assert_array_equal(tables[0].llr, tables[1].llr)
    np.testing.assert_array_equal(tables[0].size, tables[1].size)
    assert tables[0].llr[0, 0] > 0.01  # the capacity hypothesis has a signature to compare


def test_the_table_of_infinite_sums_is_nan_without_a_warning() -> None:
    """A model that blew up (an infinite increment) makes the capacity sums infinite: the table reports
    lambda NaN for it, the other hypotheses as before, and raises no RuntimeWarning at every sample (the
    detector asks for the table at every sample)."""
    banks = SignatureBanks(1, 1, ("capacity", "offset"), (0, 0), onset_every=10, window=10, t_s=1.0)
    one = np.ones((1, 1))
    with np.errstate(all="ignore"):
        banks.update(0, one, np.array([0.5]), one, 0.5 * one, np.array([True]))
        banks.predict(one, np.zeros((1, 1)), np.zeros(1), np.array([np.inf]))
        banks.update(1, one, np.array([0.5]), one, 0.5 * one, np.array([True]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tab = banks.table()
    assert np.isnan(tab.llr[0, 0])
    assert tab.llr[0, 1] == pytest.approx((0.5 + 0.25) ** 2 / (1 + 0.25), rel=1e-12)
