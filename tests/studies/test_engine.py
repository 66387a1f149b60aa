"""Studies on a real Dask LocalCluster with 2 process workers, small furnace, 12-s runs.

One cluster serves the module.  The oracle for a case's numbers is the same scenario run directly in this
process with ``ClosedLoop`` (runs are deterministic for a seed).
"""

from __future__ import annotations

import dataclasses
import json
import threading

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

from twin.config import small_config
from twin.runs.loop import ClosedLoop
from twin.runs.metrics import METRIC_KEYS
from twin.scenario import PointsReference
from twin.studies.cases import expand
from twin.studies.cluster import study_client
from twin.studies.engine import run_study
from twin.studies.spec import parse_study

BASE = {"duration": 12.0, "reference": {"setpoint": 900.0, "t_E": 6.0}}
UNREACHABLE = {"points": [[1.0, 280.0]]}  # below the coldest surroundings (300 K): outside the furnace's limits


def _with_unreachable(cases):
    """The grid's second reference replaced by ``UNREACHABLE``, past the study's own checks (which refuse it,
    as POST /api/runs does): a case the worker cannot run, as a client of another version could send it.
    The worker's check of the scenario against the furnace's limits fails it; the study must go on."""
    out = []
    for c in cases:
        if c.params["reference"] != BASE["reference"]:
            bad = c.scenario.model_copy(update={"reference": PointsReference.model_construct(points=[(1.0, 280.0)])})
            c = dataclasses.replace(c, scenario=bad, params={**c.params, "reference": UNREACHABLE})
        out.append(c)
    return out


@pytest.fixture(scope="module")
def client(radiation_cache):
    with study_client(workers=2) as (cl, n):
        assert n == 2
        yield cl


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def mixed(client, cfg, tmp_path_factory):
    """4 cases: two TC-noise levels x (a reachable, an unreachable reference)."""
    spec = parse_study({"name": "mixed", "base": BASE,
                        "grid": {"reference": [BASE["reference"], {"setpoint": 950.0, "t_E": 6.0}],
                                 "tc_noise": [0.5, 2.0]}})
    out = tmp_path_factory.mktemp("mixed")
    progress = []
    summary = run_study(spec, cfg, out, client=client, on_progress=progress.append,
                        cases=_with_unreachable(expand(spec, cfg)))
    return spec, out, summary, progress


def test_cases_run_on_both_workers_and_tables_load_once_per_worker(mixed):
    _spec, out, summary, _ = mixed
    recs = [json.loads(p.read_text()) for p in (out / "cases").glob("*.json")]
    assert len(recs) == 4
    workers = {r["worker"] for r in recs}
    assert len(workers) == 2
    # the radiation tables are loaded by the first case of each worker, never again
    assert sum(r["radiation_loaded"] for r in recs) == len(workers)
    assert summary["workers"] == 2


def test_a_failed_case_is_recorded_and_the_study_goes_on(mixed):
    _spec, out, summary, progress = mixed
    by_status = {}
    for c in summary["cases"]:
        by_status.setdefault(c["status"], []).append(c)
    assert len(by_status["done"]) == 2 and len(by_status["failed"]) == 2
    for c in by_status["failed"]:
        assert c["params"]["reference"] == UNREACHABLE and c["metrics"] is None
        assert "outside the reachable range" in c["error"] and "ValidationError" in c["error"]
    assert summary["failed"] == 2 and summary["computed"] == 4
    assert progress[-1].finished == 4 and progress[-1].failed == 2
    report = (out / "study.md").read_text()
    assert "## Failed cases" in report and "outside the reachable range" in report


def test_results_table_columns_and_values_match_a_direct_run(mixed, cfg, small_radiation):
    spec, out, summary, _ = mixed
    table = pq.read_table(out / "results.parquet")
    cols = table.column_names
    assert cols[:5] == ["index", "key", "status", "grid_point", "sample"]
    for c in ("reference", "tc_noise", *METRIC_KEYS, "setup_s", "plan_s", "run_s", "worker", "error", "scenario"):
        assert c in cols, c
    assert table.num_rows == 4
    assert pacsv.read_csv(out / "results.csv").num_rows == 4
    rows = table.to_pylist()
    assert [r["index"] for r in rows] == [0, 1, 2, 3]
    assert [r["tc_noise"] for r in rows] == [0.5, 2.0, 0.5, 2.0]
    done = [r for r in rows if r["status"] == "done"]
    assert all(r["error"] is None for r in done) and all(r["mean_error_steady_max"] is None for r in rows[2:])
    # oracle: the second case (noise 2 K) run here, directly
    case = expand(spec, cfg)[1]
    loop = ClosedLoop(cfg, case.scenario, small_radiation)
    for _ in loop.run():
        pass
    direct = loop.metrics()
    for k in METRIC_KEYS:
        assert rows[1][k] == pytest.approx(direct[k], rel=1e-9), k
    assert rows[1]["key"] == case.key


def test_json_shape_of_product_md(mixed):
    _spec, out, summary, _ = mixed
    for k in ("cases", "computed", "skipped", "failed", "workers", "wall_s", "results"):
        assert k in summary, k
    assert summary["results"] == str(out / "results.parquet")
    for c in summary["cases"]:
        assert set(c) >= {"key", "params", "status", "metrics", "error"}
        assert c["status"] in ("done", "failed", "skipped")
        assert "out" not in c  # no --keep-series
    assert json.loads((out / "summary.json").read_text())["cases"] == json.loads(json.dumps(summary["cases"]))
    assert summary["timing"]["overhead_fraction"] is not None


def test_stop_then_rerun_resumes_and_skips_done_cases(client, cfg, tmp_path):
    spec = parse_study({"base": BASE, "grid": {"tc_noise": [0.2, 0.4, 0.6]}})
    stop = threading.Event()

    def first_only(p):
        if p.finished - p.skipped >= 1:
            stop.set()

    first = run_study(spec, cfg, tmp_path, client=client, on_progress=first_only, stop=stop)
    done_first = {c["key"] for c in first["cases"] if c["status"] == "done"}
    assert 1 <= len(done_first) <= 2 and first["pending"] >= 1
    assert pq.read_table(tmp_path / "results.parquet").column("status").to_pylist().count("pending") >= 1

    second = run_study(spec, cfg, tmp_path, client=client, keep_series=False)
    skipped = {c["key"] for c in second["cases"] if c["status"] == "skipped"}
    assert skipped == done_first
    assert second["computed"] == 3 - len(done_first) and second["pending"] == 0
    statuses = pq.read_table(tmp_path / "results.parquet").column("status").to_pylist()
    assert statuses == ["done"] * 3

    third = run_study(spec, cfg, tmp_path, client=client)
    assert third["computed"] == 0 and third["skipped"] == 3 and third["workers"] == 0


def test_keep_series_writes_each_cases_timeseries(client, cfg, tmp_path):
    spec = parse_study({"base": BASE, "monte_carlo": {"n": 2, "seed": 5,
                                                      "mismatch.alpha": {"dist": "uniform", "low": -0.2, "high": 0.2}}})
    summary = run_study(spec, cfg, tmp_path, client=client, keep_series=True)
    for c in summary["cases"]:
        assert c["status"] == "done"
        with np.load(f"{c['out']}/timeseries.npz") as z:
            assert json.loads(str(z["scenario"]))["mismatch"]["alpha"] == c["params"]["mismatch.alpha"]
            assert len(z["t"]) == 121  # samples 0 .. 12 s at t_s = 0.1 s
    assert (tmp_path / "figures" / "distributions.png").is_file()
