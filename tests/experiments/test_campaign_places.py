"""One closed loop for a campaign's TC4 places (issue 21): what it writes for each place must be what a run with
TC4 there alone writes, bit for bit (``twin.experiments.campaign_places``).  The oracle is the run alone: the
code path the campaign took before, one loop per place."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twin.config import small_config
from twin.experiments.campaign import TC4_POSITIONS
from twin.experiments.campaign_places import PlaceLoop, shares_loop
from twin.experiments.campaign_runs import CampaignRun, run_campaign_group, run_campaign_run
from twin.furnace.simulated import SimulatedFurnace
from twin.scenario import FaultSpec, Scenario

PLACES = [tuple(p) for p in TC4_POSITIONS]


def _scenario(tc4: tuple[float, float], **extra: Any) -> Scenario:
    data = {"duration": 2.0, "reference": {"setpoint": 600.0, "t_E": 10.0}, "tc4": list(tc4), "seed": 3,
            "truth": "independent", **extra}
    return Scenario.model_validate(data)


def _furnace(tc4, radiation, truth_radiation, others=(), faults=()) -> SimulatedFurnace:
    return SimulatedFurnace.for_scenario(small_config(), _scenario(tc4, faults=faults), radiation,
                                         truth_radiation=truth_radiation, other_tc4=others)


def test_other_places_read_what_tc4_reads_there_alone(small_radiation, small_truth_radiation):
    """The furnace's other TC4 places (honest truth: lagged, biased TCs; an offset and then a dropout on TC4)
    against furnaces with TC4 at each place alone, 40 samples of heating; the furnace's own readings do not move
    either.  Catches another TC's noise draw or bias given to the other places, a draw of their own (which would
    also shift the furnace's stream), a lag they skip, faults they miss."""
    faults = [FaultSpec(at=1.0, target="TC4", kind="offset", value=5.0),
              FaultSpec(at=3.0, target="TC4", kind="dropout")]
    shared = _furnace(PLACES[0], small_radiation, small_truth_radiation, PLACES[1:], faults)
    alone = [_furnace(p, small_radiation, small_truth_radiation, faults=faults) for p in PLACES]
    u = np.linspace(0.3, 1.0, small_config().n_groups)
    for j in range(40):
        t = j * shared.t_s
        got = [shared.read(t), *shared.other_tc4_readings(t)]
        for mine, theirs in zip(got, (f.read(t) for f in alone), strict=True):
            np.testing.assert_array_equal(mine.values, theirs.values)
            assert mine.status == theirs.status
        for f in (shared, *alone):
            f.apply(u, t)
    assert got[1].status[3] == "bad" and np.isfinite(got[1].values[:3]).all()  # the dropout reached the places


def _task(tmp: Path, name: str, scenario: Scenario) -> CampaignRun:
    return CampaignRun(name, scenario.seed, str(tmp / name), scenario.to_json(), small_config().digest(),
                       own_truth=True, figures=False)


@pytest.mark.parametrize("estimator", [{}, {"estimator": {"shadow": {"motion": "averaged", "calibrate": False}}}],
                         ids=["default", "with-shadow"])
def test_a_shared_loop_writes_each_place_as_its_run_alone(tmp_path, small_radiation, small_truth_radiation,
                                                           estimator):
    """Three TC4 places as one loop (run_campaign_group) against each place's run alone (the campaign's code
    before): every array of each run's record (TC4's readings, statuses and estimate at its place, a shadow
    estimator's too; the header's positions and scenario) and every metric equal, bit for bit.  Catches a place
    given the shared run's TC4 estimate or positions, another TC's noise, a header left at the first place."""
    cfg = small_config()
    local = (cfg, small_radiation, small_truth_radiation)
    plans: dict[Any, Any] = {}
    tasks = [_task(tmp_path / "shared", f"fixed_tc4_{p[0]:g}", _scenario(p, **estimator)) for p in PLACES]
    alone = [_task(tmp_path / "alone", f"fixed_tc4_{p[0]:g}", _scenario(p, **estimator)) for p in PLACES]
    got = run_campaign_group(tasks, local=local, plan_cache=plans)
    want = [run_campaign_run(t, local=local, plan_cache=plans) for t in alone]
    tc4 = []
    for g, w, tg, tw in zip(got, want, tasks, alone, strict=True):
        assert g["metrics"] == w["metrics"] and g["model_error"] == w["model_error"]
        assert json.loads(Path(tg.folder, "metrics.json").read_text()) == json.loads(
            Path(tw.folder, "metrics.json").read_text())
        with np.load(Path(tg.folder, "timeseries.npz")) as a, np.load(Path(tw.folder, "timeseries.npz")) as b:
            assert sorted(a.files) == sorted(b.files)
            for k in a.files:
                assert np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), k
            tc4.append(a["tc"][:, 3])
        assert Path(tg.folder, "scenario.json").read_bytes() == Path(tw.folder, "scenario.json").read_bytes()
    assert not np.array_equal(tc4[0], tc4[1]) and not np.array_equal(tc4[1], tc4[2])  # the places do differ


def test_runs_that_differ_in_more_than_tc4_do_not_share_a_loop():
    same = [_scenario(p) for p in PLACES]
    assert shares_loop(same)
    assert not shares_loop([same[0], _scenario(PLACES[1], seed=4)])
    assert not shares_loop([_scenario(p, tc_noise=0.0) for p in PLACES])  # TC4's stuck test could then fire
    assert not shares_loop([_scenario(p, faults=[FaultSpec(at=1.0, target="TC4", kind="dropout")]) for p in PLACES])


def test_a_place_takes_no_live_changes():
    place = PlaceLoop.__new__(PlaceLoop)
    with pytest.raises(ValueError, match="no live changes"):
        place.set_faults([])
