"""Issue 15, findings 1 and 10 on the twin's side: plans bounded by the run, cancellable, coalesced,
and a change in force only when its plan is.

Finding 1: the feedforward planned over about 1.2 t_E whatever the run's length (t_E = 3600 s for a 5 s
run: a 4320 s horizon of 4320 knots, 13.6 GB and minutes of both cores).  Finding 10: a change was
"applied" before its re-plan ran, re-plans queued without limit, a failed re-plan left the change in force.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from twin.config import small_config
from twin.control.budget import PlanBudget, PlanCancelled, PlanTooLarge
from twin.control.feedforward import solve_feedforward
from twin.control.ocp_grid import MAX_KNOTS, plan_grid
from twin.control.reference import reference_trajectory
from twin.model.discrete import discrete_model
from twin.runs.loop import ClosedLoop
from twin.runs.replanning import Superseded
from twin.scenario import Scenario, TransitionReference


@pytest.fixture(scope="module")
def model(small_radiation):
    return discrete_model(small_config(), small_radiation, None)


def test_finding_01_request_bounded_by_run(model) -> None:
    """The horizon ends with the run (plus one knot interval); a long one holds v over longer intervals."""
    cfg = small_config()
    ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=3600.0), 300.0)
    unbounded = plan_grid(model, ref, 0.0, cfg)
    assert unbounded.horizon == pytest.approx(cfg.feedforward.beta * 3600.0)  # section 4.1: beta t_E
    assert unbounded.K <= MAX_KNOTS  # the K^2 arrays of the OCP stay bounded (was 4320 knots)
    bounded = plan_grid(model, ref, 0.0, cfg, t_stop=5.0)
    assert bounded.horizon <= 5.0 + bounded.interval + 1e-9
    assert bounded.K * bounded.interval >= 5.0  # ... and still covers the run's last sample
    late = plan_grid(model, ref, 100.0, cfg, t_stop=102.0)  # a re-plan 2 s before the end
    assert late.horizon <= 2.0 + late.interval + 1e-9 and late.K >= 2
    # the estimate says what the unbounded plan would have cost, the bounded one is tiny
    assert bounded.estimate(model).memory_mb < 0.01 * unbounded.estimate(model).memory_mb


def test_finding_01_loop_plans_only_its_duration(small_radiation) -> None:
    sc = Scenario.model_validate({"reference": {"setpoint": 1100.0, "t_E": 3600.0}, "duration": 5.0})
    loop = ClosedLoop(small_config(), sc, small_radiation)
    plan = loop.changes.current.plan
    assert plan.t[-1] <= 5.0 + 1.0 + 1e-9, plan.t[-1]  # one 1 s knot interval past the end, not 4320 s
    snaps = list(loop.run())
    assert snaps[-1].t == pytest.approx(5.0)


def test_finding_01_plan_beyond_budget_is_refused_with_why(model) -> None:
    cfg = small_config()
    ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=3600.0), 300.0)
    theta0 = np.full(model.n, 300.0)
    with pytest.raises(PlanTooLarge, match=r"plan over \d+ s .* needs about \d+ MB, this server allows 1 MB"):
        solve_feedforward(model, theta0, 0.0, ref, cfg, budget=PlanBudget(max_wall_s=600.0, max_memory_mb=1.0))
    with pytest.raises(PlanTooLarge, match=r"would take about \d+ s .* allows 0.5 s"):
        solve_feedforward(model, theta0, 0.0, ref, cfg, budget=PlanBudget(max_wall_s=0.5, max_memory_mb=1e6))


def test_finding_01_a_plan_is_cancelled_within_a_second(model) -> None:
    cfg = small_config()
    ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=600.0), 300.0)
    budget = PlanBudget(max_wall_s=600.0)
    threading.Timer(0.5, budget.cancel.cancel).start()
    t0 = time.monotonic()
    with pytest.raises(PlanCancelled):
        solve_feedforward(model, np.full(model.n, 300.0), 0.0, ref, cfg, budget=budget)
    assert time.monotonic() - t0 < 0.5 + 5.0  # a 600 s plan takes minutes; the cancel acts at the next knot


def _background_loop(small_radiation, **kw) -> ClosedLoop:
    # long enough that the loop, stepped while the plans are solved, does not end first on a loaded machine
    sc = Scenario.model_validate({"reference": {"setpoint": 900.0, "t_E": 20.0}, "duration": 3600.0, **kw})
    loop = ClosedLoop(small_config(), sc, small_radiation, background=True)
    for _ in range(5):
        loop.step()
    return loop


def _step_until(loop: ClosedLoop, futures, timeout: float = 300.0) -> None:
    end = time.monotonic() + timeout
    while not all(f.done() for f in futures) and time.monotonic() < end:
        loop.step()
        time.sleep(0.01)
    assert all(f.done() for f in futures)


def test_finding_10_change_in_force_only_with_its_plan(small_radiation) -> None:
    loop = _background_loop(small_radiation)
    old_ref, old_plan = loop.changes.reference, loop.changes.current.plan
    fut = loop.set_reference(TransitionReference(setpoint=700.0, t_E=5.0))
    s = loop.step()  # the plan is not ready: the old reference and plan go on
    assert not fut.done()
    assert s.T_ref == pytest.approx(float(old_ref(s.t))) and loop.changes.current.plan is old_plan
    _step_until(loop, [fut])
    t_applied = fut.result()  # the run time of the first sample on the new plan
    assert loop.changes.current.plan is not old_plan and loop.changes.current.plan.t0 <= t_applied
    later = [loop.step() for _ in range(100)]
    assert later[-1].T_ref == pytest.approx(700.0)  # 5 s transition after the plan came in
    assert loop.changes.reference_spec.setpoint == 700.0
    loop.close()


def test_finding_10_replans_coalesce_latest_wins(small_radiation) -> None:
    loop = _background_loop(small_radiation)
    futures = [loop.set_reference(TransitionReference(setpoint=700.0 + 10 * k, t_E=5.0)) for k in range(10)]
    _step_until(loop, futures)
    outcomes = []
    for f in futures:
        exc = f.exception()
        outcomes.append("superseded" if isinstance(exc, Superseded) else ("applied" if exc is None else repr(exc)))
    assert outcomes == ["superseded"] * 9 + ["applied"], outcomes
    events = [e for _ in range(3) for e in loop.step().events]
    s = [loop.step() for _ in range(100)][-1]
    assert s.T_ref == pytest.approx(790.0)  # the latest change is the one in force
    assert len([e for e in events if e.startswith("re-planned")]) <= 1
    loop.close()


def test_finding_10_other_kinds_ride_along(small_radiation) -> None:
    """A reference change, then an oscillation change before the first was planned: one plan has both."""
    from twin.scenario import OscillationSpec

    loop = _background_loop(small_radiation)
    f_ref = loop.set_reference(TransitionReference(setpoint=750.0, t_E=5.0))
    f_osc = loop.set_oscillation(OscillationSpec(enabled=True, amplitude=0.02, period=4.0))
    _step_until(loop, [f_ref, f_osc])
    assert f_ref.result() == f_osc.result()  # in force from the same sample
    assert [loop.step() for _ in range(100)][-1].T_ref == pytest.approx(750.0)
    assert max(abs(loop.step().eta) for _ in range(40)) > 0.01
    loop.close()


def test_finding_10_failed_replan_changes_nothing(small_radiation, monkeypatch) -> None:
    from twin.control import feedforward

    loop = _background_loop(small_radiation)
    before, old_ref = loop.changes.reference_spec, loop.changes.reference

    def fail(*a, **k):
        raise feedforward.FeedforwardError("feedforward OCP failed: IPOPT status Infeasible_Problem_Detected",
                                           "Infeasible_Problem_Detected")

    monkeypatch.setattr("twin.control.replan.solve_feedforward", fail)
    fut = loop.set_reference(TransitionReference(setpoint=700.0, t_E=5.0))
    _step_until(loop, [fut])
    with pytest.raises(feedforward.FeedforwardError):
        fut.result()
    snaps = [loop.step() for _ in range(60)]
    assert any("re-planning failed" in str(e) for e in loop.timeseries()["event_text"])
    assert loop.changes.reference_spec is before  # the old reference is still in force
    assert snaps[-1].T_ref == pytest.approx(float(old_ref(snaps[-1].t)))
    loop.close()


def test_finding_01_replan_beyond_budget_fails_and_changes_nothing(small_radiation) -> None:
    sc = Scenario.model_validate({"reference": {"setpoint": 900.0, "t_E": 20.0}, "duration": 3600.0})
    loop = ClosedLoop(small_config(), sc, small_radiation, background=True,
                      budget=PlanBudget(max_wall_s=600.0, max_memory_mb=40.0))
    loop.step()
    fut = loop.set_reference(TransitionReference(setpoint=1000.0, t_E=3000.0))
    _step_until(loop, [fut], timeout=60.0)
    with pytest.raises(PlanTooLarge, match="MB"):
        fut.result()
    assert loop.changes.reference_spec.setpoint == 900.0
    loop.close()


def test_the_budget_not_the_interactive_default_limits_ipopt(model, monkeypatch) -> None:
    """With a budget, IPOPT's wall-time limit is the budget's remaining time (a server's ``plan_max_s``, a campaign's
    BATCH_MAX_WALL_S), not ``solve_feedforward``'s interactive 120 s: a campaign on a loaded machine ended when one
    plan hit 120 s.  Without a budget the default stays."""
    import twin.control.feedforward as ff
    from twin.control.budget import BATCH_MAX_WALL_S

    seen: list[float] = []
    real = ff._ipopt_options

    def spy(max_iter, max_wall_s, extra):
        seen.append(float(max_wall_s))
        return real(max_iter, max_wall_s, extra)

    monkeypatch.setattr(ff, "_ipopt_options", spy)
    cfg = small_config()
    ref = reference_trajectory(TransitionReference(setpoint=800.0, t_E=20.0), 300.0)
    theta0 = np.full(model.n, 300.0)
    ff.solve_feedforward(model, theta0, 0.0, ref, cfg, horizon=30.0, budget=PlanBudget(max_wall_s=BATCH_MAX_WALL_S))
    ff.solve_feedforward(model, theta0, 0.0, ref, cfg, horizon=30.0)
    assert BATCH_MAX_WALL_S - 60.0 < seen[0] <= BATCH_MAX_WALL_S and seen[1] == 120.0
    assert BATCH_MAX_WALL_S >= 600.0  # a batch plan waits: 5x what a plan took at load 14 (27 iterations, 120 s)


def test_a_campaign_run_plans_on_the_batch_budget(monkeypatch) -> None:
    """The campaign's runs give their loop a budget of BATCH_MAX_WALL_S (the test stops at the loop's construction)."""
    import twin.runs.loop as loop_module
    from twin.control.budget import BATCH_MAX_WALL_S
    from twin.experiments import campaign_runs

    got: dict[str, object] = {}

    class Stop(Exception):
        pass

    def fake_loop(*args, **kwargs):
        got.update(kwargs)
        raise Stop

    monkeypatch.setattr(loop_module, "ClosedLoop", fake_loop)
    from twin.radiation import radiation_model
    from twin.scenario import Scenario

    cfg = small_config()
    task = campaign_runs.CampaignRun(name="fixed_tc4_0.5", seed=0, folder="unused",
                                     scenario_json=Scenario.model_validate({"truth": "shared"}).model_dump_json(),
                                     furnace_digest=cfg.digest(), own_truth=False)
    with pytest.raises(Stop):
        campaign_runs.run_campaign_run(task, local=(cfg, radiation_model(cfg), None))
    budget = got["budget"]
    assert isinstance(budget, PlanBudget) and budget.max_wall_s == BATCH_MAX_WALL_S
