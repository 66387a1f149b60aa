"""What an injected fault does to the simulated furnace's readings and lamps (twin/furnace/simulated/faults.py),
checked sample by sample against the definitions (product.md, "faults")."""

from __future__ import annotations

import numpy as np
import pytest

from twin.furnace.simulated.faults import FaultInjector
from twin.scenario import FaultSpec

GROUPS = ("T1h", "T2h", "T3h", "T4h", "T1v", "T2v")


def _f(**kw) -> FaultSpec:
    return FaultSpec.model_validate(kw)


def test_tc_faults_sample_by_sample() -> None:
    inj = FaultInjector(GROUPS, [_f(at=1.0, target="TC1", kind="drift", value=2.0),
                                 _f(at=0.5, target="TC2", kind="stuck"),
                                 _f(at=0.2, target="TC3", kind="dropout"),
                                 _f(at=0.0, target="TC4", kind="offset", value=-5.0)])
    rows = []
    for j in range(16):
        t = 0.1 * j
        values, status = inj.readings(t, np.array([900.0, 800.0 + j, 700.0, 600.0]))
        rows.append((t, values, status))
    t, v, st = rows[15]  # t = 1.5 s
    assert v[0] == pytest.approx(900.0 + 2.0 * 0.5)  # drift since 1.0 s
    assert v[1] == 805.0  # stuck at what it read at 0.5 s (800 + 5)
    assert np.isnan(v[2]) and st[2] == "bad"  # dropout: no value, status bad
    assert v[3] == 595.0 and st[3] == "good"  # offset; a stuck or offset TC does not know it
    assert rows[1][1][2] == 700.0 and rows[2][2][2] == "bad"  # dropout from the sample at 0.2 s
    assert rows[9][1][0] == 900.0 and rows[11][1][0] == pytest.approx(900.2)


def test_lamp_faults_and_what_the_lamps_deliver() -> None:
    inj = FaultInjector(GROUPS, [_f(at=0.0, target="T2h", kind="failed"),
                                 _f(at=0.0, target="T2v", kind="derate", value=0.25)])
    u = np.array([0.5, 0.7, 0.2, 1.3, 0.0, 0.8])
    np.testing.assert_allclose(inj.delivered(0.0, u), [0.5, 0.0, 0.2, 1.0, 0.0, 0.2])  # clipped to [0, 1]


def test_schedule_counts_from_now_and_an_empty_list_clears() -> None:
    inj = FaultInjector(GROUPS, [_f(at=0.0, target="T1h", kind="failed")])
    assert inj.delivered(10.0, np.ones(6))[0] == 0.0
    inj.take_events()
    inj.schedule([_f(at=2.0, target="TC1", kind="offset", value=3.0)], t_now=10.0)
    assert inj.delivered(10.0, np.ones(6))[0] == 1.0  # the old list is gone
    assert [f.at for f in inj.in_force()] == [12.0]
    assert inj.readings(11.9, np.full(4, 500.0))[0][0] == 500.0
    assert inj.readings(12.0, np.full(4, 500.0))[0][0] == 503.0
    events = inj.take_events()
    assert events[0].startswith("faults cleared at t = 10.0 s: T1h failed")
    assert events[1] == "fault injected: TC1 offset 3 K at t = 12.0 s"
    with pytest.raises(ValueError, match="T9x"):
        inj.schedule([FaultSpec.model_construct(at=0.0, target="T9x", kind="failed", value=None)], 0.0)


def test_simulated_furnace_applies_them(small_radiation) -> None:
    from twin.config import small_config
    from twin.furnace.simulated import SimulatedFurnace

    cfg = small_config()
    ok = SimulatedFurnace(cfg, small_radiation, tc_noise=0.0)
    bad = SimulatedFurnace(cfg, small_radiation, tc_noise=0.0, faults=[_f(at=0.0, target="T2v", kind="failed")])
    u = np.zeros(6)
    u[5] = 1.0  # only T2v on: the failed furnace gets no heat from the lamps
    for j in range(20):
        ok.apply(u, 0.1 * j)
        bad.apply(u, 0.1 * j)
    assert ok.true_field().mean() > bad.true_field().mean() + 1.0
    assert bad.read(2.0).status == ("good",) * 4
    bad.set_faults([_f(at=0.0, target="TC1", kind="dropout")], 2.0)
    assert bad.read(2.0).status[0] == "bad" and bad.faults_in_force()[0].at == 2.0
