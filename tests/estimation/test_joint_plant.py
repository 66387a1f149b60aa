"""The position-aware and the calibrating estimator against the full-order plant (no inverse crime).

The plant is the FD model of twin.furnace.simulated (c_p(T), lambda(T), its own integration, 26 x 17 cells,
TC noise) and the estimators use the reduced FE model (15 x 7 nodes, constant c_p): they differ in
structure, not only in parameters.

Which seeds tuned what: the EKF weights (q0, q1) were tuned on noise seeds 0-2 (default_furnace.toml);
the calibration priors and random walks on seed 21 (small furnace, 240-600 s runs); the seeds below
(31, 32, 41, 42) were used for nothing else.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from twin.config import small_config
from twin.estimation.choice import build_estimator
from twin.furnace.simulated import SimulatedFurnace
from twin.model.discrete import discrete_model
from twin.model.tables import model_tables
from twin.runs.loop import ClosedLoop
from twin.runs.metrics import oscillation_amplitude
from twin.scenario import EstimatorChoice, OscillationSpec, Scenario

CFG = small_config()
#: the controller re-planned with the calibration (off by default, see default_furnace.toml [calibration])
FOLLOWS = CFG.with_overrides({"calibration.controller_follows": True})
SETPOINT = 1100.0
OSC = OscillationSpec(enabled=True, amplitude=0.048, period=18.0)  # the paper's 3 L_h, 0.15 t_E


def _open_loop_oscillating(radiation, seed: int) -> dict[str, np.ndarray]:
    """Constant powers holding 1100 K (averaged model), oscillating plant, estimates 50 K off at the start."""
    tables = model_tables(CFG, radiation)
    u = discrete_model(CFG, radiation, OSC, tables=tables).hold_powers(SETPOINT)
    furnace = SimulatedFurnace(CFG, radiation, tc4=(0.625, 0.5), tc_noise=1.0, seed=seed, oscillation=OSC)
    estimators = {m: build_estimator(EstimatorChoice(motion=m, calibrate=False), tables, OSC, CFG, 350.0)
                  for m in ("averaged", "position_aware")}
    phi4 = tables.fe.phi(np.asarray(furnace.tc_positions[3:]))
    out: dict[str, list[float]] = {"t": [], "averaged": [], "position_aware": []}
    for j in range(int(round(240.0 / CFG.sampling.t_s))):
        t = j * CFG.sampling.t_s
        r = furnace.read(t)
        eta = furnace.motion(t).eta
        out["t"].append(t)
        for name, est in estimators.items():
            theta = est.update(r.for_estimator()).theta
            out[name].append(float((phi4 @ theta)[0] - r.values[3]))
            est.predict(u, eta)
        furnace.apply(u, t)
    return {k: np.asarray(v) for k, v in out.items()}


@pytest.mark.slow
@pytest.mark.parametrize("seed", [31, 32])
def test_oscillating_specimen_estimated_by_both_estimators(small_radiation, seed) -> None:
    run = _open_loop_oscillating(small_radiation, seed)
    t = run["t"]
    late, steady = t >= 60.0, t >= 180.0
    for name in ("averaged", "position_aware"):
        e = run[name]
        assert abs(e[0]) > 40.0  # the initial 50 K offset was really there
        # the paper's bound for TC4 is 3 % oscillating and 1.5 % fixed: measured 0.60-0.65 % here
        assert np.abs(e[late]).max() / SETPOINT < 0.01, name
    amp = {name: oscillation_amplitude(t[steady], run[name][steady], OSC.period)
           for name in ("averaged", "position_aware")}
    # the averaged model misses the motion: an error at the oscillation frequency (measured 2.3-2.4 K);
    # the model at eta(t_j) removes most of it (measured 0.5 K): at least halved (issue 11)
    assert amp["averaged"] > 1.0
    assert amp["position_aware"] < 0.5 * amp["averaged"], amp


@pytest.fixture(scope="module")
def weaker_lamps(small_radiation):
    """Closed loop on a plant whose lamps give 10 % less than the model's (nothing else changed)."""
    runs = {}
    for seed in (41, 42):
        scenario = Scenario.model_validate({
            "reference": {"setpoint": SETPOINT, "t_E": 60.0}, "duration": 240.0, "seed": seed, "truth": "shared",
            "mismatch": {"lamp_efficiency": -0.1}, "estimator": {"motion": "position_aware", "calibrate": True}})
        loop = ClosedLoop(FOLLOWS, scenario, small_radiation)
        for _ in loop.run():
            pass
        runs[seed] = loop.timeseries()
    return runs


@pytest.mark.slow
def test_calibration_learns_weaker_lamps(weaker_lamps) -> None:
    for seed, ts in weaker_lamps.items():
        lamp = ts["parameters"][:, 0]
        sigma = ts["parameter_sigma"][:, 0]
        t = ts["t"]
        # stated time: by the end of a 240 s run (t_E = 60 s heat-up, then hold) the lamp efficiency is
        # within 2 % (absolute, of the nominal) of the plant's -10 %
        assert abs(lamp[-1] - (-0.1)) < 0.02, (seed, lamp[-1])
        assert sigma[-1] < 0.02 and sigma[-1] < sigma[0] / 4  # and the filter knows it learned it
        # it moves towards it from the nominal model: at the start the estimate is the prior (0)
        assert lamp[0] == pytest.approx(0.0, abs=0.01) and (t[-1] > 200.0)


@pytest.mark.slow
def test_controller_follows_the_calibration(weaker_lamps) -> None:
    """The controller's model is re-planned with the calibrated lamps (events), and its feedforward then
    carries the power the weaker lamps need: the feedback's share of the power falls to what the plan does not
    know, (1 + eta_planned) / (1 + eta_true) - 1 with eta_true = -0.1 (the plant's mismatch), because the
    integrator gives up what the new feedforward carries (twin.control.lqg.carried_integrator).

    Measured on seed 41 (re-plans at 90.6 s with -5.0 % and 150.6 s with -8.1 %, each once the estimated mean
    was within calibration.replan_settled of the reference; the value then moves to -9 %, within the 3 %
    threshold): sum(u) / sum(u_ff) - 1 = 0.184 over 60-100 s (the nominal plan), 0.021 over 180-240 s against
    the plan's gap 0.919 / 0.9 - 1 = 0.021.  At the first re-plan the total power does not jump (2.240 -> 2.241;
    seed 42: 2.217 -> 2.239); with the integrator kept whole (planted) it jumped to 2.350 (the integrator made up
    the lamps a second time) and the estimated mean was 3.9 K above the reference 10 s later, against 1.8 K.
    (Over 180-240 s both end near the gap: the LQG's integrator unwinds within a minute here.)"""
    for ts in weaker_lamps.values():
        replans = [e for e in ts["event_text"] if e.startswith("calibration at")]
        assert 1 <= len(replans) <= 240.0 / small_config().calibration.replan_interval + 1
        assert any("lamp_efficiency -" in e for e in replans)
        t, u, u_ff = ts["t"], ts["u"], ts["u_ff"]
        t_last = float(re.search(r"at t = ([\d.]+) s", replans[-1]).group(1))
        planned = float(re.search(r"lamp_efficiency ([-+\d.]+) %", replans[-1]).group(1)) / 100.0
        before, after = (t >= 60.0) & (t < 100.0), t >= max(180.0, t_last + 20.0)  # nominal, then followed
        share = {k: u[m].sum() / u_ff[m].sum() - 1.0 for k, m in (("before", before), ("after", after))}
        assert share["before"] > 0.06, share  # the nominal plan misses the weaker lamps' power
        gap = (1.0 + planned) / (1.0 - 0.1) - 1.0  # the part of the lamps' deficit the plan does not know
        assert share["after"] == pytest.approx(gap, abs=0.008), (share, gap)
        j = int(round(float(re.search(r"at t = ([\d.]+) s", replans[0]).group(1)) / CFG.sampling.t_s))
        assert abs(u[j].sum() - u[j - 1].sum()) < 0.03, (u[j - 1].sum(), u[j].sum())  # bumpless
