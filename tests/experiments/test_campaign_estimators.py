"""campaign --estimator default|paper|both: the paper's estimator beside the default (issue 11, item 6).

Oracle: hand-made experiment results; run_campaign is replaced by a stub that records what it was asked.
"""

from __future__ import annotations

import argparse
import json

import pytest

from twin.config import small_config
from twin.experiments import campaign as camp
from twin.scenario import PAPER_ESTIMATOR


def _result(estimator: str, tc4: float, osc_amp: float | None) -> dict:
    metrics = {"tc4_error_steady_max": tc4, "mean_error_transient_max": 0.01}
    fixed = {"name": "fixed_tc4_0.5", "oscillation": False, "tc4": [0.5, 0.5], "metrics": dict(metrics),
             "model_error": {}, "seeds": []}
    osc = {"name": "oscillating_tc4_0.5", "oscillation": True, "tc4": [0.5, 0.5],
           "metrics": {**metrics, "tc4_error_oscillation_amplitude": osc_amp}, "model_error": {}, "seeds": []}
    return {"experiments": [fixed, osc], "paper": camp.PAPER, "truth": "independent", "seeds": [0],
            "estimator": {"name": estimator}}


def test_paper_estimator_is_the_papers() -> None:
    assert camp.ESTIMATORS["default"] is None  # the scenario's own default
    paper = camp.ESTIMATORS["paper"]
    assert paper is not None and (paper.motion, paper.calibrate, paper.shadow) == (
        PAPER_ESTIMATOR.motion, PAPER_ESTIMATOR.calibrate, None)
    with pytest.raises(ValueError, match="estimator must be one of"):
        camp.run_campaign(small_config(), None, estimator="kalman")  # type: ignore[arg-type]


def test_comparison_table_marks_each_side() -> None:
    before, after = _result("paper", 0.006, 0.002)["experiments"], _result("default", 0.004, 0.0005)["experiments"]
    table = camp.comparison_table(before, after)
    rows = {line.split(" | ")[0].strip("| "): line for line in table.splitlines()}
    # 0.6 % is above the fixed bound 0.5 % (✗), 0.4 % below; oscillating bound 3 %: neither marked
    assert "0.60 % ✗ -> 0.40 % |" in rows["tc4_error_steady_max"]
    assert rows["tc4_error_steady_max"].endswith("| 0.60 % -> 0.40 % |")
    assert "| n/a | 0.20 % -> 0.05 % |" in rows["tc4_error_oscillation_amplitude"]


def test_both_runs_the_paper_into_its_own_folder(tmp_path, monkeypatch, capsys) -> None:
    asked = []

    def fake(cfg, out, t_E, sink_factories=(), *, seeds, truth, estimator, **_):
        asked.append((out, estimator))
        out.mkdir(parents=True, exist_ok=True)
        return _result(estimator, 0.004 if estimator == "default" else 0.006, 0.001)

    monkeypatch.setattr(camp, "run_campaign", fake)
    args = argparse.Namespace(t_e=None, seeds=5, out=str(tmp_path), truth="independent", estimator="both", json=True)
    assert camp.campaign_command(small_config(), args) == 0
    assert asked == [(tmp_path, "default"), (tmp_path / "paper_estimator", "paper")]
    printed = json.loads(capsys.readouterr().out)
    assert printed["estimator"]["name"] == "default" and printed["paper_estimator"]["estimator"]["name"] == "paper"
    assert printed["experiments"][0]["metrics"]["tc4_error_steady_max"] == 0.004  # product.md shape: the default's
    report = (tmp_path / "campaign.md").read_text()
    assert "The paper's estimator beside the default" in report and "0.60 % ✗ -> 0.40 %" in report
