"""The twin's parametric model F(theta, u; eta, p) (twin.model.parametric, eq. 12a with eq. 11 and the
calibrated parameters of eq. 15): its input matrix, its rate, its positions and a live oscillation switch.

Oracles: finite differences of the model's own rhs (f is affine in u with a constant capacity), the identity
F = theta + t_s f of eq. (12a), the hat weights of the table nodes (twin.physics.motion.hat_interval, tested in
tests/physics) and a model built afresh for the other motion.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.model.parametric import ParametricModel
from twin.model.tables import Parameters, model_tables
from twin.scenario import OscillationSpec

OSC = OscillationSpec(enabled=True, amplitude=0.02, period=4.0)
CAL = ("lamp_efficiency", "emissivity")


@pytest.fixture(scope="module")
def tables(small_radiation):
    return model_tables(small_config(), small_radiation)


@pytest.mark.parametrize("motion", ["position_aware", "averaged"])
def test_input_matrix_against_finite_differences(tables, motion):
    """d f / d u at a position between two table nodes, with calibrated parameters (and without)."""
    model = ParametricModel(tables, OSC, motion=motion, calibrated=CAL)
    theta, u = np.linspace(700.0, 900.0, tables.n), np.full(tables.m, 0.4)
    eta = 0.3 * OSC.amplitude
    for p in (Parameters(lamp_efficiency=-0.12, emissivity=0.05), None):
        B = model.input_matrix(eta, p)
        f0 = model.rhs(theta, u, eta, p)
        for i in range(tables.m):
            du = np.zeros(tables.m)
            du[i] = 0.1
            np.testing.assert_allclose((model.rhs(theta, u + du, eta, p) - f0) / 0.1, B[:, i], rtol=1e-9, atol=1e-9)
    # the lamp efficiency scales it, the emissivity moves it (a fifth more lamp power: 1.2 x)
    np.testing.assert_allclose(model.input_matrix(eta, Parameters(lamp_efficiency=0.2)),
                               1.2 * model.input_matrix(eta), rtol=1e-12)
    assert not np.allclose(model.input_matrix(eta, Parameters(emissivity=0.05)), model.input_matrix(eta))


def test_the_rate_is_the_step_over_t_s(tables):
    model = ParametricModel(tables, OSC, motion="position_aware", calibrated=CAL)
    theta, u = np.linspace(700.0, 900.0, tables.n), np.linspace(0.1, 0.9, tables.m)
    p = Parameters(lamp_efficiency=0.1, emissivity=-0.05, convection=0.2)
    for eta in (0.0, 0.013, -0.02):
        np.testing.assert_allclose(model.step(theta, u, eta, p),
                                   theta + tables.t_s * model.rhs(theta, u, eta, p), rtol=1e-14)
    # the lamps heat: more power, faster rate everywhere they reach
    assert np.all(model.rhs(theta, u + 0.1, 0.0, p) >= model.rhs(theta, u, 0.0, p))


def test_positions_are_the_hat_weights_of_the_table_nodes(tables):
    from twin.physics.motion import hat_interval

    aware = ParametricModel(tables, OSC, motion="position_aware")
    eta_nodes = [float(v) for v in tables.eta_nodes]
    assert len(eta_nodes) >= 3
    for eta in (eta_nodes[0], 0.5 * (eta_nodes[1] + eta_nodes[2]), 0.25 * eta_nodes[1] + 0.75 * eta_nodes[2],
                eta_nodes[-1]):
        k, w = hat_interval(eta_nodes, eta)
        got = aware.positions(eta)
        assert [weight for _, weight in got] == pytest.approx([1.0 - w] + ([w] if w > 0.0 else []))
        np.testing.assert_array_equal(got[0][0].B, tables.B[k])  # node k alone
        if w > 0.0:
            np.testing.assert_array_equal(got[1][0].B, tables.B[k + 1])
    averaged = ParametricModel(tables, OSC, motion="averaged")
    ((node, weight),) = averaged.positions(0.013)  # the period average, wherever the specimen is
    assert weight == 1.0 and node is averaged.positions(-0.02)[0][0]
    np.testing.assert_array_equal(node.B, averaged.B)


def test_a_live_oscillation_switch_gives_the_model_built_for_it(tables):
    """``with_oscillation`` equals a model built afresh with the new motion, and leaves the original alone."""
    fixed = ParametricModel(tables, None, calibrated=CAL)
    theta, u = np.linspace(750.0, 950.0, tables.n), np.full(tables.m, 0.5)
    p = Parameters(lamp_efficiency=-0.05, emissivity=0.02)
    before = fixed.rhs(theta, u, 0.0, p)
    switched = fixed.with_oscillation(OSC)
    fresh = ParametricModel(tables, OSC, calibrated=CAL)
    assert switched.oscillation is OSC and fixed.oscillation is None
    np.testing.assert_allclose(switched.rhs(theta, u, 0.0, p), fresh.rhs(theta, u, 0.0, p), rtol=1e-13)
    np.testing.assert_allclose(switched.A, fresh.A, rtol=1e-13)
    assert not np.allclose(switched.rhs(theta, u, 0.0, p), before)  # the premise: the motion matters
    np.testing.assert_array_equal(fixed.rhs(theta, u, 0.0, p), before)
    assert switched.calibrated == CAL and switched.motion == fixed.motion
    back = switched.with_oscillation(None)
    np.testing.assert_allclose(back.rhs(theta, u, 0.0, p), before, rtol=1e-13)


def test_unknown_calibration_parameters_are_named(tables):
    with pytest.raises(ValueError, match=r"unknown calibration parameters \['absorptivity'\]"):
        ParametricModel(tables, None, calibrated=("lamp_efficiency", "absorptivity"))
    # the calibrated parameters are kept in the order of PARAMETERS, whatever order they were given in
    assert ParametricModel(tables, None, calibrated=("emissivity", "lamp_efficiency")).calibrated == CAL
