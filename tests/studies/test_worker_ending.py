"""A study case's record says how its run ended, as the CLI's metrics.json and the server's run record do: through
the one run object (``twin.runs.session.RunSession``), so a case that fails half-way still says why and when."""

from __future__ import annotations

import json

from twin.studies.worker import CaseTask, run_case

# a few samples of a heat-up on the small furnace, on the model's own plant (no truth tables to trace)
SCENARIO = {"duration": 1.0, "reference": {"setpoint": 400.0, "t_E": 10.0}, "truth": "shared", "seed": 0}


def _case(small_radiation) -> tuple[CaseTask, dict]:
    from twin.config import small_config

    cfg = small_config()  # small_radiation: the tables are in the test cache the worker reads
    return CaseTask("c0", cfg.digest(), json.dumps(SCENARIO)), cfg.model_dump(mode="json")


def test_a_finished_case_records_its_ending(small_radiation) -> None:
    rec = run_case(*_case(small_radiation))
    assert rec["status"] == "done", rec["error"]
    assert (rec["ending"], rec["ending_reason"]) == ("finished", None)
    assert rec["metrics"]["status"] == "finished" and rec["metrics"]["status_reason"] is None  # as metrics.json


def test_a_case_that_fails_half_way_records_error_and_when(small_radiation, monkeypatch) -> None:
    from twin.runs.guards import EstimateDiverged
    from twin.runs.loop import ClosedLoop

    step = ClosedLoop.step

    def diverging(self):
        if self.j == 4:
            raise EstimateDiverged("t = 0.4 s: planted divergence; the lamps were switched off")
        return step(self)

    monkeypatch.setattr(ClosedLoop, "step", diverging)
    rec = run_case(*_case(small_radiation))
    assert rec["status"] == "failed" and rec["metrics"] is None
    assert rec["ending"] == "error"
    assert rec["ending_reason"] == "EstimateDiverged: t = 0.4 s: planted divergence; the lamps were switched off"
    assert rec["error"] == rec["ending_reason"]


def test_the_results_table_has_the_endings(small_radiation) -> None:
    from twin.studies.store import results_table

    class Case:  # the fields results_table reads of a twin.studies.cases.Case
        index, key, grid_point, sample, params = 0, "c0", 0, 0, {}

        class scenario:  # noqa: N801
            @staticmethod
            def to_json() -> str:
                return json.dumps(SCENARIO)

    table = results_table([Case()], {"c0": run_case(*_case(small_radiation))}, [])
    assert table.column("ending").to_pylist() == ["finished"]
    assert table.column("ending_reason").to_pylist() == [None]
