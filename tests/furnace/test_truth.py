"""The simulated furnace's truth: latent heat with its energy balance, the independent furnace of a scenario,
and ``"truth": "shared"`` as the plant of before, bit for bit."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated import SimulatedFurnace
from twin.furnace.simulated.energy import power_balance, stored_energy
from twin.furnace.simulated.plant import Plant
from twin.furnace.simulated.thermocouples import Thermocouples
from twin.furnace.simulated.truth import deviations, with_latent_heat
from twin.physics.materials import Steel
from twin.physics.motion import eta_function
from twin.runs.loop import ClosedLoop
from twin.scenario import Mismatch, OscillationSpec, Scenario

CFG = small_config()
OSC = OscillationSpec(enabled=True, amplitude=0.048, period=18.0)
L = CFG.truth.material.latent_heat  # 18 kJ/kg over 1000-1150 K


def test_latent_heat_is_a_triangle_in_cp_and_all_of_it_in_the_enthalpy():
    model, truth = Steel.from_config(CFG), Steel.from_config(with_latent_heat(CFG))
    lo, hi = CFG.truth.material.transformation_range
    mid = 0.5 * (lo + hi)
    # c_p gains 2 L / (hi - lo) = 240 J/(kg K) at the middle, nothing outside the range
    assert truth.heat_capacity(mid) - model.heat_capacity(mid) == pytest.approx(2 * L / (hi - lo), rel=1e-12)
    T = np.linspace(300.0, 1300.0, 1001)
    outside = (T <= lo) | (T >= hi)
    np.testing.assert_allclose(truth.heat_capacity(T)[outside], model.heat_capacity(T)[outside], rtol=1e-12)
    np.testing.assert_allclose(truth.conductivity(T), model.conductivity(T), rtol=1e-12)  # lambda untouched
    # the enthalpy integral carries it: all above the range, half at its middle, none below
    dh = truth.enthalpy(T) - model.enthalpy(T)
    np.testing.assert_allclose(dh[T >= hi], L, rtol=1e-12)
    np.testing.assert_allclose(dh[T <= lo], 0.0, atol=1e-8)
    assert truth.enthalpy(mid) - model.enthalpy(mid) == pytest.approx(L / 2, rel=1e-12)
    # none: the model's own tables stay as they are
    assert with_latent_heat(CFG.with_overrides({"truth.material.latent_heat": 0.0})).material == CFG.material


def test_energy_balance_through_the_transformation(small_truth_radiation):
    """Stored enthalpy (latent heat included) = integral of absorbed - emitted - convective - holder."""
    plant = Plant(with_latent_heat(CFG), small_truth_radiation, deviations(CFG, None))
    eta = eta_function(OSC)
    U = np.array([1.0, 1.0, 0.9, 1.0, 1.0, 0.9])
    state = plant.start(np.full(plant.n, 950.0))
    E0 = stored_energy(plant, state.T)
    dt, n = 0.1, 400
    power = []
    for j in range(n + 1):
        f = power_balance(plant, state.T, U, eta(j * dt))
        power.append(f["absorbed"] - f["emitted"] - f["convective"] - f["holder"])
        if j < n:
            state = plant.advance(state, U, dt, eta)
    assert plant.fillet_mean(state.T) > 1160.0  # the fillet went through the whole range
    dE = stored_energy(plant, state.T) - E0
    integral = float(np.trapezoid(power, dx=dt))
    # trapezoid quadrature of the sampled power and the explicit integrator: measured ~1e-5 relative
    assert abs(dE - integral) < 1e-4 * abs(dE)
    # the latent heat is a large part of it: an enthalpy without it would miss the balance 100x over
    latent = float(plant.capacity_factor * np.sum(plant.steel.enthalpy(state.T) - Steel.from_config(CFG).enthalpy(
        state.T)))
    assert latent > 0.02 * dE


def test_an_independent_furnace_is_not_the_model(small_radiation, small_truth_radiation):
    sc = Scenario(mismatch=Mismatch(alpha=0.1, emissivity=0.02))
    f = SimulatedFurnace.for_scenario(CFG, sc, small_radiation, truth_radiation=small_truth_radiation)
    assert f.truth is not None and f.plant.radiation is not small_radiation
    assert not np.array_equal(f.plant.radiation.exchange, small_radiation.exchange)
    # the scenario's mismatch adds to the furnace's own deviations (-5 % / +30 % / -10 %)
    assert f.plant.mismatch.alpha == pytest.approx(0.4)
    assert f.plant.mismatch.emissivity == pytest.approx(-0.03)
    assert f.plant.mismatch.lamp_efficiency == pytest.approx(-0.1)
    assert f.plant.steel.enthalpy(1200.0) - Steel.from_config(CFG).enthalpy(1200.0) == pytest.approx(L)
    assert Scenario().truth == "independent"  # the default everywhere


def _old_plant_run(small_radiation, sc: Scenario, us: np.ndarray) -> tuple[list, list]:
    """The simulated furnace as it was before issue 10, from its parts: the plant on the model's table with
    the scenario's mismatch, bilinear TCs, Gaussian noise from default_rng(seed)."""
    plant = Plant(CFG, small_radiation, sc.mismatch)
    tcs = Thermocouples(CFG, CFG.tc_positions(sc.tc4))
    rng = np.random.default_rng(sc.seed)
    eta = eta_function(sc.oscillation)
    state = plant.start(np.full(plant.n, CFG.specimen.initial_temperature), 0.0)
    readings, fields = [], []
    for j, u in enumerate(us):
        readings.append(tcs.read(state.T, rng, sc.tc_noise))
        state = plant.advance(state, u, CFG.sampling.t_s, eta)
        fields.append(state.T.copy())
        assert state.t == pytest.approx((j + 1) * CFG.sampling.t_s)
    return readings, fields


def test_shared_truth_is_the_plant_of_before_bit_for_bit(small_radiation):
    sc = Scenario(truth="shared", oscillation=OSC, tc4=(0.375, 0.5), seed=11, tc_noise=1.5,
                  mismatch=Mismatch(alpha=0.2, lamp_efficiency=-0.05))
    us = np.clip(np.random.default_rng(2).uniform(-0.1, 1.1, (80, 6)), -0.2, 1.2)
    old_readings, old_fields = _old_plant_run(small_radiation, sc, us)
    f = SimulatedFurnace.for_scenario(CFG, sc, small_radiation)
    for j, u in enumerate(us):
        t = j * CFG.sampling.t_s
        np.testing.assert_array_equal(f.read(t).values, old_readings[j])
        f.apply(u, t)
        np.testing.assert_array_equal(f.true_field(), old_fields[j])


def test_a_shared_run_is_the_closed_loop_on_the_plant_of_before(small_radiation):
    """The default loop of a "shared" scenario and a loop on the old furnace record the same run."""
    sc = Scenario(truth="shared", duration=3.0, reference={"setpoint": 700.0, "t_E": 10.0}, seed=3)
    a = ClosedLoop(CFG, sc, small_radiation)
    old = SimulatedFurnace(CFG, small_radiation, mismatch=sc.mismatch, tc4=sc.tc4, tc_noise=sc.tc_noise,
                           seed=sc.seed, oscillation=sc.oscillation)
    b = ClosedLoop(CFG, sc, small_radiation, furnace=old)
    for _ in a.run():
        next(b.run())
    ta, tb = a.timeseries(), b.timeseries()
    for key in ("tc", "u", "T_mean_hat", "field_true"):
        np.testing.assert_array_equal(ta[key], tb[key])


def test_the_twin_side_never_reads_the_truth():
    """The model, the estimator and the controller keep the paper's assumptions: no word of [truth]."""
    root = Path(__file__).resolve().parents[2] / "twin"
    offenders = []
    for part in ("model", "estimation", "control"):
        for path in (root / part).rglob("*.py"):
            if re.search(r"\.truth\b|truth_radiation|with_latent_heat|furnace\.simulated", path.read_text()):
                offenders.append(str(path))
    assert not offenders
