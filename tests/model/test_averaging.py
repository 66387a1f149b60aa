"""Exact period-average weights (paper eq. 11b) against brute-force time quadrature."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from twin.model.averaging import averaged_matrices
from twin.physics.motion import average_weights, hat_weights, oscillation_weights
from twin.scenario import OscillationSpec

NODES = np.linspace(-0.05, 0.05, 13)  # the default table: 13 positions on [-eta_max, eta_max]


def _time_average(nodes: np.ndarray, amplitude: float, period: float, n: int = 400_000) -> np.ndarray:
    """(1/Pi) int_0^Pi hat_n(a sin(2 pi t / Pi)) dt by the midpoint rule on n samples.

    np.interp on unit vectors is the hat function, written independently of twin.model.averaging.
    """
    t = (np.arange(n) + 0.5) * period / n
    eta = amplitude * np.sin(2 * np.pi * t / period)
    return np.array([np.interp(eta, nodes, e).mean() for e in np.eye(len(nodes))])


@pytest.mark.parametrize("amplitude", [0.048, 0.05, 0.0123, 0.008333])
@pytest.mark.parametrize("period", [18.0, 3.7])
def test_weights_equal_the_time_average(amplitude: float, period: float) -> None:
    w = oscillation_weights(NODES, amplitude)
    ref = _time_average(NODES, amplitude, period)
    # midpoint rule on a periodic integrand with kinks: error ~ (kinks x h^2 x curvature), below 1e-7
    # for 4e5 samples (measured 1e-9..1e-8); 1e-6 keeps the test robust yet sharp against a wrong weight.
    np.testing.assert_allclose(w, ref, atol=1e-6)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)  # partition of unity, exact in closed form
    assert (w >= 0).all()


def test_fixed_specimen_is_the_special_case() -> None:
    np.testing.assert_allclose(average_weights(NODES, None), np.eye(13)[6], atol=0)
    np.testing.assert_allclose(average_weights(NODES, OscillationSpec(enabled=False)), np.eye(13)[6], atol=0)
    np.testing.assert_allclose(oscillation_weights(NODES, 0.0), np.eye(13)[6], atol=0)
    # eta = 0.01 m lies between nodes 7 (1/120 m) and 8 (2/120 m): weights 0.8 and 0.2
    w = hat_weights(NODES, 0.01)
    np.testing.assert_allclose(w[7:9], [0.8, 0.2], rtol=1e-12)
    assert w.sum() == pytest.approx(1.0, abs=1e-15)


def test_amplitude_outside_the_table_is_refused() -> None:
    with pytest.raises(ValueError, match="exceeds"):
        oscillation_weights(np.linspace(-0.02, 0.02, 5), 0.03)


def test_averaged_matrices_equal_the_time_average_of_interpolated_tables() -> None:
    rng = np.random.default_rng(3)
    nodes = np.linspace(-0.05, 0.05, 5)
    tables = SimpleNamespace(eta_nodes=nodes, P1=rng.normal(size=(5, 4, 6)), P2=rng.normal(size=(5, 4, 3)))
    spec = OscillationSpec(enabled=True, amplitude=0.048, period=18.0)
    P1, P2 = averaged_matrices(tables, spec)
    ref = _time_average(nodes, 0.048, 18.0)
    # same quadrature bound as above times max |P| ~ 3 and 5 terms
    np.testing.assert_allclose(P1, np.tensordot(ref, tables.P1, axes=1), atol=2e-5)
    np.testing.assert_allclose(P2, np.tensordot(ref, tables.P2, axes=1), atol=2e-5)
