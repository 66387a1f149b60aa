"""Issue 15, finding 2: TC noise of 10 K or more made the estimator diverge (the scenario allowed 50 K):
the estimated mean went to -1.5e8 K with every lamp group at 100 %, the run ended in ``ValueError: cannot
convert float NaN to integer`` in the plant, and absurd metrics were stored.

Now a divergence check (twin/runs/guards.py) stops the loop with the lamps off before an absurd sample
reaches the furnace or the record, and the scenario's noise limit is what the estimator is shown to
tolerate here, across the whole allowed range (small furnace, short runs).
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.limits import TC_NOISE_MAX_K
from twin.runs.guards import DivergenceGuard, EstimateDiverged
from twin.runs.loop import ClosedLoop
from twin.scenario import Scenario


def _scenario(**kw) -> Scenario:
    return Scenario.model_validate({"reference": {"setpoint": 1000.0, "t_E": 20.0}, "duration": 40.0, **kw})


@pytest.fixture(scope="module")
def plans():
    return {}


def test_finding_02_guard_names_what_is_wrong() -> None:
    guard = DivergenceGuard.for_furnace(small_config(), tc_noise=1.0)
    ok = {"field": np.full((2, 3), 900.0), "T_mean": 900.0, "tc": np.full(4, 901.0), "tc_hat": np.full(4, 900.0),
          "u": np.full(6, 0.5)}
    assert guard.problem(**ok) is None
    assert "not a finite number" in guard.problem(**{**ok, "T_mean": float("nan")})
    assert "lamp group powers" in guard.problem(**{**ok, "u": np.array([0.5, np.nan, 0, 0, 0, 0])})
    assert "below" in guard.problem(**{**ok, "field": np.full((2, 3), -1.5e8)})
    assert "above" in guard.problem(**{**ok, "field": np.full((2, 3), 1.0e5)})
    # lost track: TC1 500 K off for 5 s (50 samples), not for a moment
    far = {**ok, "tc": np.array([1400.0, 901.0, 901.0, 901.0])}
    assert all(guard.problem(**far) is None for _ in range(49))
    assert "TC1 has been more than 150 K from the estimate for 50 samples" in guard.problem(**far)
    assert guard.problem(**ok) is None  # the count restarts


class _Recorder:
    """A furnace wrapper that remembers the inputs applied to it."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.applied: list[np.ndarray] = []

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def apply(self, u, t) -> None:
        self.applied.append(np.asarray(u, float).copy())
        self.inner.apply(u, t)


def test_finding_02_divergence_stops_the_loop_lamps_off(small_radiation, plans, monkeypatch) -> None:
    from twin.furnace.simulated import SimulatedFurnace

    cfg, sc = small_config(), _scenario()
    furnace = _Recorder(SimulatedFurnace.for_scenario(cfg, sc, small_radiation))
    loop = ClosedLoop(cfg, sc, small_radiation, furnace=furnace, plan_cache=plans)
    update = loop.estimator.update

    def diverging(y, learn=True):  # an estimator that runs off after 2 s, as the noisy EKF did
        state = update(y, learn)
        if loop.j >= 20:
            state.theta[:] = -1.5e8 * (loop.j - 19)
        return state

    monkeypatch.setattr(loop.estimator, "update", diverging)
    with pytest.raises(EstimateDiverged, match=r"t = 2.0 s: the estimated field reaches -1.5e\+08 K.*lamps"):
        list(loop.run())
    assert np.all(furnace.applied[-1] == 0.0)  # the last input the furnace got: lamps off
    assert len(furnace.applied) == 21  # 20 sane samples, then the off command
    arrays = loop.timeseries()
    assert len(arrays["t"]) == 20 and np.all(np.isfinite(arrays["T_mean_hat"]))  # data kept, nothing absurd
    m = loop.metrics()
    def leaves(d):  # the calibration and shadow metrics are objects (product.md)
        for v in d.values():
            yield from leaves(v) if isinstance(v, dict) else (v,)

    assert all(v is None or not np.isfinite(v) or abs(v) < 1.0 for v in leaves(m)), m


@pytest.mark.slow
@pytest.mark.parametrize("noise", [0.0, TC_NOISE_MAX_K / 2, TC_NOISE_MAX_K])
def test_finding_02_estimator_tolerates_the_allowed_noise(small_radiation, plans, noise) -> None:
    """Across the scenario's whole TC noise range the estimate stays with the plant (no guard trips)."""
    for seed in (0, 1):
        loop = ClosedLoop(small_config(), _scenario(tc_noise=noise, seed=seed), small_radiation, plan_cache=plans)
        snaps = list(loop.run())  # EstimateDiverged would fail the test
        err = np.array([abs(s.T_mean_hat - s.true_mean) for s in snaps])
        # the estimate's fillet mean vs the plant's, after the first 2 s (the estimator starts from the TC mean):
        # within a few noise sigmas of the three TCs' average plus the model error seen at 1 K (12 K, measured)
        assert float(err[20:].max()) < 20.0 + 3.0 * noise, (noise, seed, float(err.max()))


def test_finding_02_noise_above_the_limit_is_refused() -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="tc_noise"):
        _scenario(tc_noise=TC_NOISE_MAX_K + 0.5)
