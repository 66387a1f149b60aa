"""``true_mean_lead_lamps_off_max``: the reference's lead over the furnace left with every lamp off, a bound no
controller beats in the transient (twin.furnace.simulated.SimulatedFurnace.lamps_off_means, kept in the run's header
as ``true_mean_lamps_off``; twin.runs.metrics.lamps_off_lead).

Oracles: the run's own true transient error (the bound is below it: lamp power only adds heat), and the same bound
made another way, by driving the furnace's public ``apply`` with u = 0 (``scripts/control_table.py``'s
``lamps_off_bound``, lamp lag and TC read included) instead of its plant directly."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated import SimulatedFurnace
from twin.limits import scenario_limits
from twin.runs.loop import ClosedLoop
from twin.scenario import parse_scenario

CFG = small_config()


def _scenario(seed: int, duration: float):
    # the paper's 1100 K, with the small furnace's t_E of 30 s (tests/experiments/test_campaign.py)
    return parse_scenario({"reference": {"setpoint": 1100.0, "t_E": 30.0}, "duration": duration, "seed": seed,
                           "truth": "independent"}, scenario_limits(CFG))


@pytest.mark.slow
def test_a_run_reports_the_bound_below_its_own_transient_error(small_radiation, small_truth_radiation, load_script):
    sc = _scenario(seed=4, duration=32.0)
    furnace = SimulatedFurnace.for_scenario(CFG, sc, small_radiation, truth_radiation=small_truth_radiation)
    loop = ClosedLoop(CFG, sc, small_radiation, furnace=furnace)
    free = loop.record.header.true_mean_lamps_off
    assert free is not None and free.shape == (301,)  # 30 s (LAMPS_OFF_WINDOW_S) at t_s = 0.1 s, from t = 0
    for _ in loop.run():
        pass
    m = loop.metrics()
    bound = m["true_mean_lead_lamps_off_max"]
    # the cold plate warms by itself faster than the reference leaves its start, and no input does better
    assert 0.0 < bound <= m["true_mean_error_transient_max"] + 1e-12
    # the same bound by the furnace's public path (apply with u = 0, its lamp lag), from a furnace of its own
    made, _ = load_script("control_table").lamps_off_bound(CFG, sc, small_radiation, seconds=30.0)
    assert bound == pytest.approx(made, abs=1e-9)
    # the bound's plant starts from the furnace's start, and leaves the run's furnace where it is
    end = furnace.true_field()
    start = furnace.lamps_off_means(lambda T: float(np.max(np.abs(T - CFG.specimen.initial_temperature))), 2)
    assert start[0] == 0.0 and 0.0 < start[1] < 5.0  # uniform 300 K, then warming by itself
    assert np.array_equal(furnace.true_field(), end)


def test_a_run_on_a_furnace_that_cannot_be_left_alone_has_no_bound(small_radiation):
    """A furnace without ``lamps_off_means`` (a real one, over OPC UA) gives no bound; neither does a simulated one
    without a truth of its own to leave alone (none: ``true_field`` is None)."""

    class Real:  # the Furnace protocol's view of a simulated furnace, without lamps_off_means
        def __init__(self, inner: SimulatedFurnace) -> None:
            self._inner = inner

        def __getattr__(self, name: str):
            if name == "lamps_off_means":
                raise AttributeError(name)
            return getattr(self._inner, name)

    sc = _scenario(seed=1, duration=1.0)
    loop = ClosedLoop(CFG, sc, small_radiation, furnace=Real(SimulatedFurnace.for_scenario(CFG, sc, small_radiation)))
    for _ in loop.run():
        pass
    assert loop.record.header.true_mean_lamps_off is None and "true_mean_lead_lamps_off_max" not in loop.metrics()


def test_a_short_run_and_a_live_change_bound_it_to_their_samples():
    """Only the samples the run has and those before its first live change count (the reference after a change is
    another one); relative to the scenario's setpoint."""
    from twin.runs import metrics as mt

    t = np.arange(6) * 0.1  # a run of 6 samples; the free response is known for 7
    ts = {"t": t, "T_ref": np.array([300.0, 300.5, 301.0, 290.0, 290.0, 290.0]), "setpoint": 1000.0,
          "true_mean_lamps_off": np.array([300.0, 302.0, 304.0, 306.0, 308.0, 310.0, 312.0]),
          "change_t": np.array([0.3])}
    out: dict = {}
    mt._extras(ts, out, t, np.zeros(6, bool), np.zeros(6))
    assert out["true_mean_lead_lamps_off_max"] == pytest.approx(0.003)  # (304 - 301) K / 1000 K at t = 0.2 s
    ts.pop("change_t")  # without the change: the lowered reference counts, to the run's last sample
    out = {}
    mt._extras(ts, out, t, np.zeros(6, bool), np.zeros(6))
    assert out["true_mean_lead_lamps_off_max"] == pytest.approx(0.020)  # (310 - 290) K / 1000 K at t = 0.5 s
