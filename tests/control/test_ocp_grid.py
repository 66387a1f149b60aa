"""The OCP's grid (twin.control.ocp_grid): plan_grid, PlanGrid.estimate, check_budget, _seconds.

No IPOPT solve and no furnace: the model is a 3-node stand-in with a Jacobian known in closed form,

    d theta / dt = f(theta, u) = -(a + c mean(u)) theta - k theta^4 + B u,

so its loss rate at a uniform temperature T and inputs u is a + c mean(u) + 4 k T^3 (1/s), the same for
every node: the fillet-mean time constant (``mean_time_constant``) is its inverse and the fastest rate
(``_fastest_rate``) is the rate itself.  With a = 0.02, c = 0.04, k = 1e-10 at half power (u = 0.5, the
linearization point plan_grid uses):

    T = 1000 K: 0.02 + 0.02 + 0.4  = 0.44 1/s   (tau = 1 / 0.44 = 2.2727 s)
    T = 1500 K: 0.02 + 0.02 + 1.35 = 1.39 1/s
    T = 1600 K: 0.02 + 0.02 + 4e-10 * 1600^3 = 1.6784 1/s

Every expected grid below is worked by hand from plan_grid's docstring (horizon beta (t_end - t0), at least
2 tau, at most the run's end plus one knot interval; knots every ``interval`` s or coarser for at most
MAX_KNOTS = 240; Heun substeps n with h |lambda_max| <= 1, h = knot interval / n).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pytest

import twin.control.lqg as lqg
import twin.control.ocp_grid as og
from twin.control.budget import PlanBudget, PlanCancelled, PlanEstimate, PlanTooLarge
from twin.control.ocp_grid import MAX_KNOTS, PlanGrid, check_budget, plan_grid

A_LOSS, C_U, K_RAD = 0.02, 0.04, 1e-10
#: a stand-in FurnaceConfig: only what plan_grid and the timed estimate read (beta of section 4.1; the
#: OCP's weights and smoothing are handed on to the shooting as they are)
CFG = SimpleNamespace(feedforward=SimpleNamespace(beta=1.2, smoothing=0.05, g0=1.0, g1=0.001))


def _rate(T: float, u: float = 0.5) -> float:
    return A_LOSS + C_U * u + 4.0 * K_RAD * T**3


@dataclass
class _Model:
    """theta+ = theta + t_s f(theta, u) (the stand-in above); records the Jacobians' arguments."""

    n: int = 3
    m: int = 4
    t_s: float = 0.5
    calls: list = field(default_factory=list)

    @property
    def c_m(self) -> np.ndarray:
        return np.full(self.n, 1.0 / self.n)

    @property
    def W(self) -> np.ndarray:
        return np.eye(self.n)

    def _B(self) -> np.ndarray:
        return np.ones((self.n, self.m))

    def step(self, theta, u):
        theta, u = np.asarray(theta, float), np.asarray(u, float)
        f = -(A_LOSS + C_U * u.mean()) * theta - K_RAD * theta**4 + self._B() @ u
        return theta + self.t_s * f

    def jac_theta(self, theta, u):
        self.calls.append(("theta", np.array(theta, dtype=object), np.array(u, dtype=object)))
        theta, u = np.asarray(theta, float), np.asarray(u, float)
        return np.eye(self.n) + self.t_s * np.diag(-(A_LOSS + C_U * u.mean()) - 4.0 * K_RAD * theta**3)

    def jac_u(self, theta, u):
        self.calls.append(("u", np.array(theta, dtype=object), np.array(u, dtype=object)))
        theta = np.asarray(theta, float)
        return self.t_s * (self._B() - C_U / self.m * theta[:, None] * np.ones((1, self.m)))


class _Ref:
    """T_ref(t): linear from T0 at t = 0 to T1 at t_end, then held (t_end given, as reference_trajectory's)."""

    def __init__(self, T0: float, T1: float, t_end: float) -> None:
        self.T0, self.T1, self.t_end = T0, T1, t_end

    def __call__(self, t):
        s = np.clip(np.asarray(t, float) / self.t_end, 0.0, 1.0)
        return self.T0 + (self.T1 - self.T0) * s


def _grid(g: PlanGrid) -> tuple:
    return (g.t0, g.horizon, g.interval, g.K, g.n_heun, g.t_end, g.T_final, g.T_hot)


def test_horizon_is_beta_times_the_transition_left() -> None:
    # heating 300 -> 1000 K over 100 s from t0 = 0: beta t_E = 1.2 x 100 = 120 s (> 2 tau = 4.5 s);
    # knots every 1 s = 2 samples of 0.5 s, K = 120; hottest 1000 K (the final value): 0.44 1/s x 1 s -> 1 substep
    g = plan_grid(_Model(), _Ref(300.0, 1000.0, 100.0), 0.0, CFG)
    assert _grid(g) == (0.0, pytest.approx(120.0, rel=1e-12), 1.0, 120, 1, 100.0, 1000.0, 1000.0)
    # from t0 = 40 s: 1.2 x 60 = 72 s, 72 knots
    g = plan_grid(_Model(), _Ref(300.0, 1000.0, 100.0), 40.0, CFG)
    assert (g.horizon, g.K, g.t0) == (pytest.approx(72.0, rel=1e-12), 72, 40.0)


def test_horizon_after_the_transition_is_two_time_constants() -> None:
    # a re-plan at 200 s of a transition that ended at 100 s: beta (100 - 200) < 0, so 2 tau at the final
    # 1000 K and half power: 2 / 0.44 = 4.545 s -> ceil(4.545 / 1 s) = 5 knots
    g = plan_grid(_Model(), _Ref(300.0, 1000.0, 100.0), 200.0, CFG)
    assert g.horizon == pytest.approx(2.0 / _rate(1000.0), rel=1e-12)
    assert (g.K, g.interval, g.T_final, g.t_end) == (5, 1.0, 1000.0, 100.0)
    # the time constant is taken at the final temperature, not at the start: held at 1500 K, 2 / 1.39 s
    g = plan_grid(_Model(), _Ref(300.0, 1500.0, 100.0), 200.0, CFG)
    assert g.horizon == pytest.approx(2.0 / _rate(1500.0), rel=1e-12) and g.K == 2  # ceil(1.44) = 2


def test_horizon_ends_with_the_run_plus_one_knot_interval() -> None:
    ref = _Ref(300.0, 1000.0, 100.0)
    # run ends at 15 s, plan from 10 s: min(1.2 x 90, 5 + 1) = 6 s, 6 knots
    g = plan_grid(_Model(), ref, 10.0, CFG, t_stop=15.0)
    assert (g.horizon, g.K) == (6.0, 6)
    # a run that ended before t0: one knot interval, and at least 2 knots
    g = plan_grid(_Model(), ref, 10.0, CFG, t_stop=8.0)
    assert (g.horizon, g.K) == (1.0, 2)
    # a given horizon is bounded the same way, and a longer run does not lengthen it
    assert plan_grid(_Model(), ref, 10.0, CFG, horizon=30.0, t_stop=15.0).horizon == 6.0
    assert plan_grid(_Model(), ref, 10.0, CFG, horizon=30.0, t_stop=500.0).horizon == 30.0


def test_long_horizons_hold_v_over_longer_intervals() -> None:
    ref = _Ref(1000.0, 1000.0, 1.0)
    # 600 s at 0.5 s samples: 240 knots of 600 / 240 = 2.5 s (5 samples) exactly, not 241
    g = plan_grid(_Model(), ref, 0.0, CFG, horizon=600.0)
    assert (g.interval, g.K, g.horizon) == (2.5, MAX_KNOTS, 600.0)
    # ... and n_heun = ceil(2.5 s x 0.44 1/s) = ceil(1.1) = 2
    assert g.n_heun == 2
    # 601 s: 5 samples would need 241 knots, so 6 samples (3 s): ceil(601 / 3) = 201 knots
    g = plan_grid(_Model(), ref, 0.0, CFG, horizon=601.0)
    assert (g.interval, g.K) == (3.0, 201)
    # a horizon of a whole number of knots is not given one more: 7 s at 1 s knots is 7 knots
    assert plan_grid(_Model(), ref, 0.0, CFG, horizon=7.0).K == 7
    # the knot interval is the nearest multiple of t_s: 1.3 s -> 3 samples (2.6 rounded), 1.5 s;
    # one shorter than half a sample is one sample
    assert plan_grid(_Model(), ref, 0.0, CFG, horizon=6.0, interval=1.3).interval == 1.5
    assert plan_grid(_Model(), ref, 0.0, CFG, horizon=6.0, interval=0.2).interval == 0.5


def test_heun_substeps_follow_the_hottest_temperature_planned_for() -> None:
    # cooling 1500 -> 1000 K: the reference at the first knot is hottest, 1.39 1/s x 1 s -> 2 substeps
    g = plan_grid(_Model(), _Ref(1500.0, 1000.0, 100.0), 0.0, CFG)
    assert (g.T_hot, g.T_final, g.n_heun) == (1500.0, 1000.0, 2)
    # a start hotter than the reference: its hottest node, 1600 K: 1.68 1/s x 1 s -> 2; at 2.5 s knots
    # (horizon 600 s) ceil(2.5 x 1.6784) = 5, where 1000 K would give 2
    theta0 = np.array([1000.0, 1600.0, 900.0])
    g = plan_grid(_Model(), _Ref(1000.0, 1000.0, 1.0), 0.0, CFG, horizon=600.0, theta0=theta0)
    assert (g.T_hot, g.n_heun) == (1600.0, 5)
    assert plan_grid(_Model(), _Ref(1000.0, 1000.0, 1.0), 0.0, CFG, horizon=600.0).n_heun == 2
    # h |lambda| <= 1 holds on every grid above, and one substep fewer would break it
    lam = _rate(1600.0)
    assert 2.5 / 5 * lam <= 1.0 < 2.5 / 4 * lam


def test_untimed_estimate_counts_the_plans_arrays() -> None:
    # 5 knots of 1.5 s (3 samples of 0.5 s), 2 Heun substeps each: 10 substeps, 15 samples
    g = PlanGrid(t0=0.0, horizon=7.5, interval=1.5, K=5, n_heun=2, t_end=0.0, T_final=1000.0, T_hot=1000.0)
    est = g.estimate(_Model())
    assert est == PlanEstimate(horizon_s=7.5, knots=5, substeps=10, samples=15, n=3, m=4)
    # a grid whose interval is not a multiple of t_s: 1.3 s -> 3 samples (2.6 rounded); 0.2 s -> 1 sample
    assert dataclasses.replace(g, interval=1.3).estimate(_Model()).samples == 15
    assert dataclasses.replace(g, interval=0.2).estimate(_Model()).samples == 5


class _Clock:
    """A stand-in for time.perf_counter that advances only when told: the timed pieces add known seconds."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def timed(monkeypatch):
    """perf_counter, CoarseShooting and riccati_step replaced by recorders: a sweep costs 8 s, a
    jac_theta + jac_u pair 0.75 s, a Riccati step 0.125 s of the fake clock (powers of two: exact sums)."""
    clock = _Clock()
    rec = SimpleNamespace(shootings=[], sweeps=[], riccati=[], clock=clock)
    monkeypatch.setattr(og.time, "perf_counter", clock)

    class Shooting(og.CoarseShooting):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            rec.shootings.append((args, kwargs))

        def sweep(self, p):
            rec.sweeps.append(np.array(p))
            out = super().sweep(p)
            clock.t += 8.0
            return out

    real_riccati = lqg.riccati_step

    def riccati(*args):
        rec.riccati.append(args)
        clock.t += 0.125
        return real_riccati(*args)

    monkeypatch.setattr(og, "CoarseShooting", Shooting)
    monkeypatch.setattr(lqg, "riccati_step", riccati)
    return rec


class _TimedModel(_Model):
    """The stand-in whose Jacobians cost 0.25 s (jac_theta) and 0.5 s (jac_u) of the fake clock when called
    at the linearization point of the timing (u = 0.5), nothing inside the sweep."""

    clock: _Clock | None = None

    def jac_theta(self, theta, u):
        if self.clock is not None and np.all(np.asarray(u) == 0.5):
            self.clock.t += 0.25
        return super().jac_theta(theta, u)

    def jac_u(self, theta, u):
        if self.clock is not None and np.all(np.asarray(u) == 0.5):
            self.clock.t += 0.5
        return super().jac_u(theta, u)


def test_timed_estimate_times_one_sweep_of_this_ocp(timed) -> None:
    model = _TimedModel()
    model.clock = timed.clock
    g = PlanGrid(t0=3.0, horizon=7.5, interval=1.5, K=5, n_heun=2, t_end=0.0, T_final=1000.0, T_hot=1000.0)
    token = []
    est = g.estimate(model, CFG, timed=True, check=lambda: token.append(1))
    # the sizes are the untimed estimate's; the times are what the fake clock says each piece took
    assert est == PlanEstimate(horizon_s=7.5, knots=5, substeps=10, samples=15, n=3, m=4, sweep_s=8.0,
                               jacobian_s=0.75, riccati_s=0.125)
    # one OCP on this grid: from the final temperature, 5 intervals of 1.5 s in 2 Heun substeps, T_ref held
    # at T_final on the 6 knots, trapezoidal weights 3 3 3 3 1.5 over 15 samples, the config's weights
    (args, kwargs), = timed.shootings
    m, th0, dt, n_heun, T_knots, weights, g0, g1, inputs = args
    assert m is model and dt == 1.5 and n_heun == 2 and (g0, g1) == (1.0, 0.001)
    np.testing.assert_array_equal(th0, [1000.0] * 3)
    np.testing.assert_array_equal(T_knots, [1000.0] * 6)
    np.testing.assert_allclose(weights, [0.2, 0.2, 0.2, 0.2, 0.1], rtol=1e-15)
    assert (inputs.m, inputs.K, inputs.width) == (4, 5, 0.05)
    # the budget's check is called at every knot of the sweep (5 knots)
    assert kwargs["check"] is not None and len(token) == 5
    # one sweep (a sweep is the cost of the whole OCP), at an even distribution d = 1/m and v = 0.5
    assert len(timed.sweeps) == 1
    np.testing.assert_array_equal(timed.sweeps[0], [0.25] * 4 + [0.5] * 5)
    # five Jacobian pairs at (T_final, u = 0.5) and five Riccati steps of the (n + 1)-state system
    at_point = [(k, th, u) for k, th, u in model.calls if np.all(u == 0.5)]
    assert [k for k, _, _ in at_point] == ["theta", "u"] * 5
    for _, th, u in at_point:
        assert th.tolist() == [1000.0] * 3 and u.tolist() == [0.5] * 4
    assert len(timed.riccati) == 5
    P, Phi, Gam, Q, r0 = timed.riccati[0]
    np.testing.assert_array_equal(P, np.eye(4))
    np.testing.assert_array_equal(Phi, np.eye(4))
    np.testing.assert_array_equal(Gam, np.ones((4, 4)))
    np.testing.assert_array_equal(Q, np.eye(4))
    assert r0 == 1.0


def test_timed_estimate_needs_the_config() -> None:
    g = PlanGrid(t0=0.0, horizon=7.5, interval=1.5, K=5, n_heun=2, t_end=0.0, T_final=1000.0, T_hot=1000.0)
    with pytest.raises(AssertionError):
        g.estimate(_Model(), None, timed=True)


_GRID = PlanGrid(t0=0.0, horizon=7.5, interval=1.5, K=5, n_heun=2, t_end=0.0, T_final=1000.0, T_hot=1000.0)


def test_check_budget_refuses_memory_before_timing(timed) -> None:
    # 5 knots, 10 substeps, 15 samples, n = 3, m = 4 (p = m + K = 9 parameters): PlanEstimate.memory_mb's words
    # 5 x 4 x 9 + 4 x 81 + 10 x 2 x (9 + 12) + 2 x 16 x 3 + 15 x 4 x 4 = 180 + 324 + 420 + 96 + 240 = 1,260,
    # 8 bytes each: 0.01008 MB
    assert _GRID.estimate(_Model()).memory_mb == pytest.approx(0.01008, rel=1e-12)
    with pytest.raises(PlanTooLarge, match="needs about 0 MB, this server allows 0.01 MB"):
        check_budget(_GRID, _TimedModel(), CFG, PlanBudget(max_wall_s=1e9, max_memory_mb=0.01))
    assert timed.shootings == [] and timed.sweeps == []  # refused before anything was run


def test_check_budget_refuses_time_and_returns_the_timed_estimate(timed) -> None:
    model = _TimedModel()
    model.clock = timed.clock
    # seconds = 30 sweeps x 8 s + 15 samples / 10 x 0.75 s + 15 x 0.125 s = 240 + 1.125 + 1.875 = 243 s
    est = check_budget(_GRID, model, CFG, PlanBudget(max_wall_s=243.0, max_memory_mb=0.0101))
    assert (est.sweep_s, est.jacobian_s, est.riccati_s, est.seconds) == (8.0, 0.75, 0.125, 243.0)
    with pytest.raises(PlanTooLarge, match="would take about 243 s .* allows 242.9 s"):
        check_budget(_GRID, model, CFG, PlanBudget(max_wall_s=242.9))


def test_check_budget_times_a_sweep_that_a_cancel_ends(timed) -> None:
    budget = PlanBudget(max_wall_s=1e9)
    budget.cancel.cancel()
    with pytest.raises(PlanCancelled):
        check_budget(_GRID, _TimedModel(), CFG, budget)


def test_seconds_is_the_median_of_the_wall_times(monkeypatch) -> None:
    clock = _Clock()
    monkeypatch.setattr(og.time, "perf_counter", clock)
    durations = iter([8.0, 1.0, 4.0, 2.0, 3.0])
    calls = []

    def f():
        calls.append(1)
        clock.t += next(durations)

    # five calls by default: the median of 8, 1, 4, 2, 3 s is 3 s (their mean 3.6 s)
    assert og._seconds(f) == 3.0 and len(calls) == 5
    durations = iter([5.0, 1.0])
    assert og._seconds(f, repeat=2) == 3.0 and len(calls) == 7  # median of two: their mean
    assert isinstance(og._seconds(lambda: None, repeat=1), float)
