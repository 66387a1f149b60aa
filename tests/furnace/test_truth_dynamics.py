"""The truth's sensor and actuator dynamics against analytic first-order responses, and their wiring
into the simulated furnace (lags, per-TC biases from the seed)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated import SimulatedFurnace
from twin.furnace.simulated.lags import held_input_step, ramp_input_step
from twin.furnace.simulated.sensors import LampLag, class1_tolerance
from twin.furnace.simulated.truth import Truth

CFG = small_config()
H = 0.1  # s, the furnace's sampling time


def test_ramp_input_lag_is_the_analytic_ramp_response():
    # tau y' = x - y, x = x0 + r t, y(0) = x0:  y = x0 + r (t - tau (1 - exp(-t / tau)))
    tau, x0, r = 0.18, 300.0, 7.0
    y, t = x0, 0.0
    for _ in range(40):
        y = ramp_input_step(y, x0 + r * t, x0 + r * (t + H), H, tau)
        t += H
        assert y == pytest.approx(x0 + r * (t - tau * (1 - math.exp(-t / tau))), abs=1e-10)
    assert x0 + r * t - y == pytest.approx(r * tau, rel=1e-6)  # settled: the reading trails by r tau


def test_ramp_input_lag_follows_a_curved_input_to_second_order():
    # x = T1 + (T0 - T1) exp(-t / theta):  y = T1 + (T0 - T1) (theta e^(-t/theta) - tau e^(-t/tau)) / (theta - tau)
    tau, theta, T0, T1 = 0.18, 5.0, 300.0, 1100.0

    def x(t: float) -> float:
        return T1 + (T0 - T1) * math.exp(-t / theta)

    def analytic(t: float) -> float:
        return T1 + (T0 - T1) * (theta * math.exp(-t / theta) - tau * math.exp(-t / tau)) / (theta - tau)

    errors = {}
    for h in (0.2, 0.1):
        y, t, err = T0, 0.0, 0.0
        for _ in range(int(round(10.0 / h))):
            y = ramp_input_step(y, x(t), x(t + h), h, tau)
            t += h
            err = max(err, abs(y - analytic(t)))
        errors[h] = err
    # the input is linear per step: error <= h^2 / 8 max|x''| = 0.04 K at h = 0.1 s; quartered per halving
    assert errors[0.1] < 0.04
    assert errors[0.2] / errors[0.1] == pytest.approx(4.0, rel=0.1)


def test_held_input_lag_is_the_analytic_step_response():
    # unit step from 0: p(t) = 1 - exp(-t / tau); the sample's mean is the integral over it / h
    tau = 0.3
    p, t = 0.0, 0.0
    for _ in range(20):
        p, mean = held_input_step(p, 1.0, H, tau)
        exact = (H - tau * (math.exp(-t / tau) - math.exp(-(t + H) / tau))) / H
        t += H
        assert p == pytest.approx(1 - math.exp(-t / tau), abs=1e-14)
        assert mean == pytest.approx(exact, abs=1e-14)
    lamps = LampLag(2, time_constant=0.0)  # no lag: the command passes, clipped like a thyristor
    np.testing.assert_array_equal(lamps.step(np.array([0.4, 1.7]), H), [0.4, 1.0])


def _truth(radiation, **changes) -> Truth:
    return replace(Truth.of(CFG, radiation), **changes)


def test_furnace_lamps_radiate_the_lagged_power(small_truth_radiation):
    truth = _truth(small_truth_radiation)
    f = SimulatedFurnace(CFG, truth.radiation, truth=truth, tc_noise=0.0)
    u = np.array([1.0, 0.8, 0.0, 0.5, 1.0, 0.6])
    state = f.plant.start(f.true_field())
    p = np.zeros(6)
    for j in range(5):  # the plant holds each sample's mean power: 1 - tau/h (1 - e^(-h/tau)) = 0.15 of a step
        f.apply(u, j * H)
        p, mean = held_input_step(p, u, H, truth.lamp_time_constant)
        state = f.plant.advance(state, mean, H, lambda t: 0.0)
        np.testing.assert_array_equal(f.true_field(), state.T)
    ideal = SimulatedFurnace(CFG, truth.radiation, truth=_truth(small_truth_radiation, lamp_time_constant=0.0),
                             tc_noise=0.0)
    for j in range(5):
        ideal.apply(u, j * H)
    assert ideal.plant.fillet_mean(ideal.true_field()) > f.plant.fillet_mean(f.true_field()) + 0.05  # lag costs heat


def test_furnace_thermocouples_lag_the_plate(small_truth_radiation):
    tau = 0.18
    truth = _truth(small_truth_radiation, tc_time_constant=tau, tc_bias=0.0)
    f = SimulatedFurnace(CFG, truth.radiation, truth=truth, tc_noise=0.0)
    u = np.full(6, 0.9)
    junction = f.thermocouples.true_values(f.true_field())
    xs = [junction.copy()]
    for j in range(60):
        np.testing.assert_allclose(f.read(j * H).values, junction, rtol=0, atol=1e-9)
        f.apply(u, j * H)
        xs.append(f.thermocouples.true_values(f.true_field()))
        junction = ramp_input_step(junction, xs[-2], xs[-1], H, tau)
    # heating at a few K/s, the readings trail the plate by tau dT/dt (the first-order lag's signature)
    rate = (xs[-1] - xs[-2]) / H
    trail = xs[-1] - f.read(6.0).values
    assert np.all(rate > 2.0)
    np.testing.assert_allclose(trail, tau * rate, rtol=0.05)


def test_biases_are_drawn_per_tc_from_the_seed_within_the_class1_band(small_truth_radiation):
    truth = _truth(small_truth_radiation, tc_time_constant=0.0)
    T0 = np.full(CFG.specimen.n_states, 1100.0)

    def readings(seed: int, bias: float, noise: float = 0.0) -> np.ndarray:
        f = SimulatedFurnace(CFG, truth.radiation, truth=replace(truth, tc_bias=bias), tc_noise=noise, seed=seed, T0=T0)
        return f.read(0.0).values

    tol = float(class1_tolerance(1100.0))  # 3.31 K at 826.85 C
    b0, b0_again, b1 = readings(0, 1.0) - 1100.0, readings(0, 1.0) - 1100.0, readings(1, 1.0) - 1100.0
    np.testing.assert_array_equal(b0, b0_again)
    assert not np.allclose(b0, b1)
    assert np.all(np.abs(b0) <= tol) and np.all(np.abs(b1) <= tol)
    assert len(set(np.round(b0, 9))) == 4  # one bias per thermocouple
    np.testing.assert_allclose(readings(0, 0.0), 1100.0, atol=1e-9)  # bias 0: none
    np.testing.assert_allclose(readings(0, 0.5) - 1100.0, 0.5 * b0, atol=1e-9)  # the scale scales them
    # the biases have a stream of their own: the noise of a seed is the same with and without them
    np.testing.assert_allclose(readings(7, 1.0, 1.0) - readings(7, 0.0, 1.0), readings(7, 1.0) - 1100.0, atol=1e-9)
    # over many seeds beta is uniform in [-1, 1]: mean 0, variance 1/3
    betas = np.concatenate([(readings(s, 1.0) - 1100.0) / tol for s in range(200)])
    assert abs(betas.mean()) < 4 * math.sqrt(1 / 3 / betas.size)
    assert betas.var() == pytest.approx(1 / 3, rel=0.1)
