"""A run's loop in its own process (backend/runs/process_loop.py) answers like the loop itself: samples, changes
whose futures settle with the step that installs their plan, refusals as the same exceptions, faults, the
series appended by the child, and a Stop while the first plan is made ends the child at once."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from backend.runs.process_loop import ProcessLoop
from twin.control.budget import PlanBudget, PlanCancelled
from twin.runs.series_store import consolidate
from twin.scenario import PointsReference, Scenario, parse_faults, parse_reference

SCENARIO = {"duration": 60.0, "reference": {"setpoint": 700.0, "t_E": 3.0}}


def test_a_loop_in_its_own_process(tmp_path, small_cfg) -> None:
    loop = ProcessLoop(small_cfg, Scenario.model_validate(SCENARIO))
    try:
        first = loop.step()
        assert first.t == 0.0 and first.field_hat.shape == (small_cfg.specimen.ny, small_cfg.specimen.nx)
        # 260 K is below what the scenario limits allow (300 K); built without them, the child's loop refuses
        # it: its ReferenceError arrives as a ValueError
        cold = PointsReference.model_construct(points=[(1.0, 900.0), (2.0, 260.0)])
        with pytest.raises(ValueError, match="unreachable"):
            loop.set_reference(cold)
        fut = loop.set_reference(parse_reference({"setpoint": 750.0, "t_E": 2.0}))
        loop.set_faults(parse_faults([{"target": "TC2", "kind": "dropout"}]))
        snaps = []
        while not fut.done() and not loop.done:
            snaps.append(loop.step())
        applied = fut.result(timeout=1)
        assert 0.0 < applied <= snaps[-1].t + 1e-9  # in force from a sample of this run
        while snaps[-1].t < applied + 2.5:  # its 2 s transition is over
            snaps.append(loop.step())
        assert snaps[-1].T_ref == pytest.approx(750.0)
        assert np.isnan(snaps[-1].tc[1])  # TC2 dropped out, in the child's furnace
        assert [f.target for f in loop.faults_in_force()] == ["TC2"]
        loop.append_series(str(tmp_path))
        arrays = consolidate(tmp_path, tmp_path / "timeseries.npz")
        assert len(arrays["t"]) == len(snaps) + 1 and "fault detected" in " ".join(arrays["event_text"])
        assert not loop.done
        assert set(loop.metrics()) >= {"mean_error_transient_max", "tc4_error_steady_max"}
    finally:
        loop.close()
    assert not loop._proc.is_alive()


def test_stop_while_the_first_plan_is_made(small_cfg) -> None:
    budget = PlanBudget(max_wall_s=600.0)
    threading.Timer(0.5, budget.cancel.cancel).start()
    t0 = time.monotonic()
    with pytest.raises(PlanCancelled):
        ProcessLoop(small_cfg, Scenario.model_validate({**SCENARIO, "duration": 3600.0}), budget=budget)
    assert time.monotonic() - t0 < 30.0
