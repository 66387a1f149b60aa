"""study.md's numbers from synthetic case rows: best case / grid point, percentiles, rank correlations, and
the timing figures (hand-off gaps, overhead) from synthetic worker clocks."""

from __future__ import annotations

import numpy as np
import pytest

from twin.studies.report import best_cases, percentiles, sensitivities
from twin.studies.spec import parse_study
from twin.studies.timing import timing_figures


def _rows(spec_doc, metric):
    """Rows like the engine's summary: params of a grid x Monte Carlo expansion and a metric from them."""
    from twin.config import small_config
    from twin.studies.cases import expand

    spec = parse_study(spec_doc)
    rows = [{"key": c.key, "index": c.index, "params": c.params, "status": "done", "error": None,
             "metrics": {"inhomogeneity_steady": metric(c.params)}} for c in expand(spec, small_config())]
    return spec, rows


def test_best_grid_point_is_ranked_by_its_median_over_the_samples():
    # period 6: values 1, 1, 1, 10 (mean 3.25, median 1); period 12: 2, 2, 2, 2 (mean 2, median 2)
    spec, rows = _rows({"grid": {"oscillation.period": [6.0, 12.0]},
                        "monte_carlo": {"n": 4, "seed": 0, "seeds": "base", "tc_noise": {"dist": "uniform",
                                                                                        "low": 0.5, "high": 1.0}}},
                       lambda p: 0.0)
    for r in rows:
        r["metrics"]["inhomogeneity_steady"] = (10.0 if r["index"] == 3 else 1.0) if r["params"][
            "oscillation.period"] == 6.0 else 2.0
    best = {b["metric"]: b for b in best_cases(spec, rows)}["inhomogeneity_steady"]
    assert best["params"] == {"oscillation.period": 6.0} and best["value"] == 1.0 and best["n"] == 4


def test_best_case_without_samples_and_failed_cases_left_out():
    spec, rows = _rows({"grid": {"tc_noise": [0.5, 1.0, 2.0]}}, lambda p: 0.01 * p["tc_noise"])
    rows[0]["status"], rows[0]["metrics"] = "failed", None
    best = {b["metric"]: b for b in best_cases(spec, rows)}["inhomogeneity_steady"]
    assert best["key"] == rows[1]["key"] and best["value"] == pytest.approx(0.01)


def test_percentiles_match_numpy():
    spec, rows = _rows({"monte_carlo": {"n": 40, "seed": 3, "tc_noise": {"dist": "uniform", "low": 0.5,
                                                                          "high": 2.0}}},
                       lambda p: p["tc_noise"] ** 2)
    values = np.array([r["metrics"]["inhomogeneity_steady"] for r in rows])
    p = percentiles(rows)["inhomogeneity_steady"]
    for q in (5, 25, 50, 75, 95):
        assert p[f"p{q}"] == pytest.approx(np.percentile(values, q))
    assert p["max"] == values.max() and p["n"] == 40


def test_rank_correlation_finds_the_driving_field():
    mc = {"n": 30, "seed": 2, "tc_noise": {"dist": "uniform", "low": 0.5, "high": 2.0},
          "mismatch.alpha": {"dist": "uniform", "low": -0.3, "high": 0.3}}
    spec, rows = _rows({"monte_carlo": mc}, lambda p: np.exp(-p["mismatch.alpha"]))  # decreasing in alpha only
    rho = sensitivities(spec, rows)["inhomogeneity_steady"]
    assert rho["mismatch.alpha"] == pytest.approx(-1.0)
    assert abs(rho["tc_noise"]) < 0.5 and "seed" not in rho


def test_timing_gaps_overhead_and_efficiency():
    def rec(worker, start, end, loaded=False):
        return {"worker": worker, "started": start, "finished": end, "setup_s": 0.5 if loaded else 0.01,
                "radiation_loaded": loaded, "plan_s": (end - start) / 2, "run_s": (end - start) / 2, "metrics_s": 0.0}

    # worker a: cases [0, 4], [4.1, 8.1]; worker b: [0, 4], [4.3, 8.3]: gaps 0.1 and 0.3 s
    recs = [rec("a", 0.0, 4.0, True), rec("a", 4.1, 8.1), rec("b", 0.0, 4.0, True), rec("b", 4.3, 8.3)]
    t = timing_figures(recs, wall_s=10.0, workers=2, fresh=recs)
    assert t["gap_s_mean"] == pytest.approx(0.2) and t["case_s"] == pytest.approx(4.0)
    assert t["setup_s"] == pytest.approx(0.01) and t["load_s"] == pytest.approx(0.5)
    assert t["overhead_fraction"] == pytest.approx((0.2 + 0.01) / 4.0)
    assert t["efficiency"] == pytest.approx(16.0 / 20.0)
    resumed = timing_figures(recs, wall_s=0.0, workers=0)  # nothing computed now: per-case figures stay
    assert resumed["case_s"] == pytest.approx(4.0) and resumed["efficiency"] is None
