"""A failed lamp group (its column of dF/du zero, as the loop's fault ride-through builds the model) is
planned with its distribution bound at 0: the OCP still solves and holds the mean with the others, the
group's feedforward is 0 at every sample, and the LQG gives it no feedback."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from twin.control.initial_guess import heating_efficiency
from twin.control.reference import reference_trajectory
from twin.control.replan import replan
from twin.model.discrete import discrete_model
from twin.scenario import TransitionReference


@pytest.fixture(scope="module")
def models(small_radiation):
    from twin.config import small_config

    cfg = small_config()
    nominal = discrete_model(cfg, small_radiation)
    gains = np.ones(nominal.m)
    gains[1] = 0.0  # T2h failed
    return cfg, nominal, dataclasses.replace(nominal, B=nominal.B * gains[None, :])


def test_heating_efficiency_of_a_dead_group_is_zero(models) -> None:
    _, nominal, failed = models
    theta = np.full(nominal.n, 900.0)
    eta = heating_efficiency(failed, theta)
    assert eta[1] == 0.0 and np.all(eta[[0, 2, 3, 4, 5]] > 0)
    # the working groups keep their ratios to each other, normalised to mean 1 over themselves
    ref = heating_efficiency(nominal, theta)[[0, 2, 3, 4, 5]]
    np.testing.assert_allclose(eta[[0, 2, 3, 4, 5]], ref / ref.mean(), rtol=1e-12)


def test_plan_without_a_failed_group(models) -> None:
    cfg, _, failed = models
    ref = reference_trajectory(TransitionReference(setpoint=800.0, t_E=20.0), 300.0)
    plan, gains = replan(failed, cfg, np.full(failed.n, 300.0), 0.0, ref, best_effort=True)
    assert plan.success, plan.status
    assert np.all(plan.u_ff[:, 1] == 0.0)
    assert plan.max_mean_error < 10.0  # K: the other groups track the transition
    assert np.all(gains.K[:, 1, :] == 0.0) and np.all(gains.K_terminal[1] == 0.0)
