"""Reduced FE model (eqs. 9-12a) against the full-order plant: open-loop heat-up to 1100 K and hold.

Constant group powers are chosen with the FE model so that its steady fillet mean is the setpoint;
both models start cold (300 K) and run 2 t_E = 240 s with those powers.  At the end of the hold the
FE field must match the plant: fillet mean within 1 % and every fillet cell within 3 % of the
setpoint (the estimator brief's bounds), for the fixed specimen and, with the time-averaged model
(eq. 11), for the oscillating plant.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated.plant import Plant
from twin.model.discrete import discrete_model
from twin.physics.motion import eta_function
from twin.scenario import OscillationSpec

CFG = small_config()
SETPOINT = 1100.0  # K, furnace.md
DURATION = 240.0  # s, 2 t_E (furnace.md: runs last 2 t_E)
SHAPE = np.array([0.9, 0.7, 0.5, 0.4, 0.6, 0.3])  # uneven groups: exercises the lamp-group mapping
OSC = OscillationSpec(enabled=True, amplitude=0.048, period=18.0)  # the paper's 3 L_h, 0.15 t_E


def _run(radiation, oscillation, distribution):
    model = discrete_model(CFG, radiation, oscillation)
    u = model.hold_powers(SETPOINT, distribution)
    plant = Plant(CFG, radiation)
    eta = eta_function(oscillation) if oscillation is not None else (lambda t: 0.0)
    state = plant.start(np.full(plant.n, CFG.specimen.initial_temperature))
    theta = np.full(model.n, CFG.specimen.initial_temperature)
    t_s = CFG.sampling.t_s
    for _ in range(int(round(DURATION / t_s))):
        state = plant.advance(state, u, t_s, eta)
        theta = model.step(theta, u)
    return model, plant, state.T, theta


@pytest.mark.slow
@pytest.mark.parametrize(
    "oscillation, distribution",
    [(None, None), (None, SHAPE), (OSC, None)],
    ids=["fixed-uniform", "fixed-shaped", "oscillating-uniform"],
)
def test_fe_model_matches_the_plant_at_the_end_of_the_hold(small_radiation, oscillation, distribution) -> None:
    model, plant, T, theta = _run(small_radiation, oscillation, distribution)
    mask = plant.fillet_mask
    fe_cells = model.M_theta @ theta
    mean_err = abs(model.c_m @ theta - plant.fillet_mean(T)) / SETPOINT
    point_err = np.max(np.abs(fe_cells - T)[mask]) / SETPOINT
    # measured (small_config, 15 x 7 nodes): mean 0.19 / 0.23 / 0.11 %, points 0.53 / 0.50 / 0.63 % (ids order)
    assert mean_err < 0.01
    assert point_err < 0.03
    # cross-check of the powers: the plant itself holds its fillet mean at the setpoint within 1 %
    assert abs(plant.fillet_mean(T) - SETPOINT) / SETPOINT < 0.01
