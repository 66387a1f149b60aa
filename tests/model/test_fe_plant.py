"""Reduced FE model (eqs. 9-12a) against the full-order plant: open-loop heat-up to 1100 K and hold.

Constant group powers are chosen with the FE model so that its steady fillet mean is the setpoint;
both models start cold (300 K) and run 2 t_E = 240 s with those powers.

* At the end of the hold the FE field must match the plant: fillet mean within 1 % and every fillet
  cell within 3 % of the setpoint (the estimator brief's bounds), for the fixed specimen and, with
  the time-averaged model (eq. 11), for the oscillating plant.
* Over the whole heat-up, against a plant with the FE model's own material model (the constant,
  enthalpy-equivalent c_p and lambda at the reference temperature, section 2.2): this isolates the
  spatial reduction (15 x 7 nodes instead of 26 x 17 cells), which must be small at every sample.
* Through the Curie peak, against the real plant: the difference is then the constant-c_p
  assumption, whose size the enthalpy table predicts (a lumped plate heated with the same energy
  differs by int_300^T (c_p / c_bar - 1) dT', at most 113 K near 830 K): the FE mean lags behind
  while the plant's c_p is below the mean, runs ahead while the plant crosses the peak, and meets
  the plant at the end.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated.plant import Plant
from twin.model.discrete import discrete_model
from twin.model.fe import FEModel
from twin.physics.materials import Steel
from twin.physics.motion import eta_function
from twin.scenario import OscillationSpec

CFG = small_config()
SETPOINT = 1100.0  # K, furnace.md
DURATION = 240.0  # s, 2 t_E (furnace.md: runs last 2 t_E)
SHAPE = np.array([0.9, 0.7, 0.5, 0.4, 0.6, 0.3])  # uneven groups: exercises the lamp-group mapping
OSC = OscillationSpec(enabled=True, amplitude=0.048, period=18.0)  # the paper's 3 L_h, 0.15 t_E


def _run(radiation, oscillation, distribution, plant_cfg=CFG):
    """Both models under the same held powers; also the per-sample fillet means and worst fillet cell (K)."""
    model = discrete_model(CFG, radiation, oscillation)
    u = model.hold_powers(SETPOINT, distribution)
    plant = Plant(plant_cfg, radiation)
    eta = eta_function(oscillation) if oscillation is not None else (lambda t: 0.0)
    state = plant.start(np.full(plant.n, CFG.specimen.initial_temperature))
    theta = np.full(model.n, CFG.specimen.initial_temperature)
    t_s = CFG.sampling.t_s
    history = []
    for _ in range(int(round(DURATION / t_s))):
        state = plant.advance(state, u, t_s, eta)
        theta = model.step(theta, u)
        worst = np.max(np.abs(model.M_theta @ theta - state.T)[plant.fillet_mask])
        history.append((model.c_m @ theta, plant.fillet_mean(state.T), worst))
    return model, plant, state.T, theta, np.array(history)


@pytest.mark.slow
@pytest.mark.parametrize(
    "oscillation, distribution",
    [(None, None), (None, SHAPE), (OSC, None)],
    ids=["fixed-uniform", "fixed-shaped", "oscillating-uniform"],
)
def test_fe_model_matches_the_plant_at_the_end_of_the_hold(small_radiation, oscillation, distribution) -> None:
    model, plant, T, theta, _ = _run(small_radiation, oscillation, distribution)
    mask = plant.fillet_mask
    fe_cells = model.M_theta @ theta
    mean_err = abs(model.c_m @ theta - plant.fillet_mean(T)) / SETPOINT
    point_err = np.max(np.abs(fe_cells - T)[mask]) / SETPOINT
    # measured (small_config, 15 x 7 nodes): mean 0.19 / 0.23 / 0.11 %, points 0.53 / 0.50 / 0.63 % (ids order)
    assert mean_err < 0.01
    assert point_err < 0.03
    # cross-check of the powers: the plant itself holds its fillet mean at the setpoint within 1 %
    assert abs(plant.fillet_mean(T) - SETPOINT) / SETPOINT < 0.01


@pytest.fixture(scope="module")
def heat_up(small_radiation):
    """The fixed-specimen heat-up on the real plant and on a plant with the FE model's material model."""
    fe = discrete_model(CFG, small_radiation, None).fe
    n = len(CFG.material.temperatures)
    same_material = CFG.with_overrides({"material.heat_capacity": [fe.heat_capacity] * n,
                                        "material.conductivity": [fe.conductivity] * n})
    return _run(small_radiation, None, None)[4], _run(small_radiation, None, None, same_material)[4]


@pytest.mark.slow
def test_fe_model_follows_a_plant_of_its_own_material_over_the_whole_heat_up(heat_up) -> None:
    history = heat_up[1]
    mean_err = np.abs(history[:, 0] - history[:, 1]) / SETPOINT
    # the spatial reduction alone: measured 0.46 K (0.04 %) at most over the heat-up, fillet cells
    # 8.6 K (0.8 %); 0.2 % and 1.5 % bound them while a wrong capacity or conduction would not fit
    assert mean_err.max() < 0.002
    assert history[:, 2].max() / SETPOINT < 0.015
    assert history[:, 1].min() < 400.0 and history[-1, 1] > 1090.0  # it did heat from cold to the setpoint


@pytest.mark.slow
def test_through_the_curie_peak_the_error_is_the_constant_heat_capacity(heat_up) -> None:
    history = heat_up[0]
    fe_mean, plant_mean = history[:, 0], history[:, 1]
    err = fe_mean - plant_mean
    # the enthalpy oracle: a lumped plate heated with the energy that brings the real steel to T has
    # T_FE - T = int_300^T (c_p / c_bar - 1) dT' (c_bar = the FE model's enthalpy-equivalent c_p)
    steel, c_bar = Steel.from_config(CFG), FEModel(CFG).heat_capacity
    T = np.linspace(300.0, 1100.0, 801)
    lag = (steel.enthalpy(T) - steel.enthalpy(300.0)) / c_bar - (T - 300.0)
    assert lag.min() < -100.0  # 113 K near 830 K: far more than the spatial error above
    # measured: the FE mean lags by up to 92 K (at a plant mean of 720 K), within the oracle's 113 K
    assert err.min() >= 1.05 * lag.min()
    below = (plant_mean > 500.0) & (plant_mean < 950.0)
    assert (err[below] < 0).all()  # c_p below its mean: the real plate heats faster
    crossing = (plant_mean > 1010.0) & (plant_mean < 1090.0)
    assert crossing.any() and err[crossing].max() > 5.0  # the plant stalls in the peak; measured +20 K
    assert abs(err[-1]) / SETPOINT < 0.01  # and they meet at the end of the hold (measured 0.46 K)
