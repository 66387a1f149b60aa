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


# ------------------------------------------------------------------ properties (hypothesis)
from hypothesis import given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@st.composite
def _tables_and_amplitudes(draw):
    """Increasing table positions (not necessarily symmetric or equally spaced) and an admissible amplitude."""
    n = draw(st.integers(2, 15))
    gaps = np.array(draw(st.lists(st.floats(0.1, 1.0), min_size=n - 1, max_size=n - 1)))
    left = draw(st.floats(0.05, 0.95))  # fraction of the span on the negative side
    nodes = np.concatenate([[0.0], np.cumsum(gaps)])
    nodes = 0.06 * (nodes / nodes[-1] - left)  # span 0.06 m, eta = 0 inside
    a_max = min(-nodes[0], nodes[-1])
    amplitude = draw(st.floats(0.0, 1.0)) * a_max
    return nodes, amplitude


@given(_tables_and_amplitudes())
def test_weights_are_a_probability_with_the_motions_moments(case) -> None:
    """For any amplitude: w_n >= 0, sum w_n = 1, and the moments of the arcsine law.

    Linear interpolation reproduces linear functions, so sum w_n eta_n is the time mean of
    a sin(.), 0; it over-estimates the convex eta^2 by at most (max gap)^2 / 4 above the true
    mean square a^2 / 2.
    """
    nodes, a = case
    w = oscillation_weights(nodes, a)
    assert (w >= 0).all()
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    assert abs(w @ nodes) <= 1e-12 * np.ptp(nodes) + 1e-15
    second = w @ nodes**2
    assert a**2 / 2 - 1e-15 <= second <= a**2 / 2 + np.max(np.diff(nodes)) ** 2 / 4 + 1e-15
    # only the nodes of the intervals the motion visits carry weight
    reach = (nodes >= -a - 1e-15) | np.r_[nodes[1:] >= -a, True]
    reach &= (nodes <= a + 1e-15) | np.r_[True, nodes[:-1] <= a]
    assert (w[~reach] == 0).all()


@given(_tables_and_amplitudes(), st.floats(0.0, 1.0))
def test_hat_weights_interpolate_linear_functions_exactly(case, s) -> None:
    nodes = case[0]
    eta = nodes[0] + s * np.ptp(nodes)
    w = hat_weights(nodes, eta)
    assert (w >= 0).all() and w.sum() == pytest.approx(1.0, abs=1e-15)
    assert np.count_nonzero(w) <= 2
    assert w @ nodes == pytest.approx(eta, abs=1e-15)


# ------------------------------------------------------------------ the interpolation in eta at its edges
def test_hat_interval_at_and_beyond_the_table_ends() -> None:
    from twin.physics.motion import TABLE_TOLERANCE, hat_interval

    nodes = [-0.05, -0.025, 0.0, 0.025, 0.05]
    assert hat_interval(nodes, -0.05) == (0, 0.0)
    assert hat_interval(nodes, 0.05) == (3, 1.0)  # the last interval, at its right end
    k, w = hat_interval(nodes, 0.0125)
    assert k == 2 and w == pytest.approx(0.5, rel=1e-12)
    assert hat_interval(nodes, 0.025) == (3, 0.0)  # on a node: the interval that starts there
    # round-off beyond an end (within TABLE_TOLERANCE of the span, at least 1 m x tol) counts as the end
    tiny = 0.5 * TABLE_TOLERANCE
    assert hat_interval(nodes, 0.05 + tiny) == (3, 1.0) and hat_interval(nodes, -0.05 - tiny) == (0, 0.0)
    for eta in (0.05 + 3 * TABLE_TOLERANCE, -0.05 - 3 * TABLE_TOLERANCE, 0.3):
        with pytest.raises(ValueError, match="outside the exchange-factor table"):
            hat_interval(nodes, eta)
    # a one-node table (no oscillation) is position independent
    assert hat_interval([0.0], 0.7) == (0, 0.0)
    np.testing.assert_array_equal(hat_weights([0.0], 0.0), [1.0])


def test_eta_function_starts_at_t0_moving_up() -> None:
    from twin.physics.motion import eta_function

    spec = OscillationSpec(enabled=True, amplitude=0.03, period=4.0)
    eta = eta_function(spec, t0=10.0)
    assert eta(10.0) == 0.0 and eta(11.0) == pytest.approx(0.03, rel=1e-12)
    assert eta(12.0) == pytest.approx(0.0, abs=1e-15)
    assert eta(13.0) == pytest.approx(-0.03, rel=1e-12) and eta(9.0) == pytest.approx(-0.03, rel=1e-12)
    # a zero amplitude or a disabled spec holds the specimen at eta = 0 whatever the period
    assert eta_function(OscillationSpec(enabled=True, amplitude=0.0, period=4.0))(1.0) == 0.0
    assert eta_function(OscillationSpec(enabled=False, amplitude=0.03, period=4.0))(1.0) == 0.0


def test_amplitude_up_to_the_table_end_is_accepted() -> None:
    nodes = np.linspace(-0.04, 0.05, 10)  # an asymmetric table: the shorter side (0.04 m) limits
    assert oscillation_weights(nodes, 0.04).sum() == pytest.approx(1.0, abs=1e-12)
    with pytest.raises(ValueError, match="exceeds"):
        oscillation_weights(nodes, 0.0401)
    # a negative amplitude is no oscillation: the fixed specimen's weights
    np.testing.assert_array_equal(oscillation_weights(nodes, -0.01), hat_weights(nodes, 0.0))


def test_the_table_tolerance_is_relative_above_a_span_of_one_and_exact_at_its_edges() -> None:
    """tol = TABLE_TOLERANCE max(1, span): absolute (1e-9) for tables in m, relative for a table in mm
    (span 100: 1e-7); a position exactly at an end +- tol is still inside, 1.5 tol beyond is outside."""
    from twin.physics.motion import TABLE_TOLERANCE, hat_interval

    mm = [-50.0, -25.0, 0.0, 25.0, 50.0]
    assert hat_interval(mm, 50.0 + 0.5e-7) == (3, 1.0) and hat_interval(mm, -50.0 - 0.5e-7) == (0, 0.0)
    with pytest.raises(ValueError, match="outside"):
        hat_interval(mm, 50.0 + 3e-7)
    m = [-0.05, 0.0, 0.05]
    tol = TABLE_TOLERANCE * 1.0
    assert hat_interval(m, -0.05 - tol) == (0, 0.0) and hat_interval(m, 0.05 + tol) == (1, 1.0)
    for eta in (0.05 + 1.5 * tol, -0.05 - 1.5 * tol):
        with pytest.raises(ValueError, match="outside"):
            hat_interval(m, eta)


def test_a_single_precision_table_gives_the_weights_of_its_values() -> None:
    """Table positions stored as float32 are taken at their values: the moments are formed in double
    precision (in float32 the weights would be off by ~1e-7)."""
    nodes32 = NODES.astype(np.float32)
    exact = oscillation_weights(nodes32.astype(float), 0.048)
    np.testing.assert_array_equal(oscillation_weights(nodes32, 0.048), exact)


def test_the_amplitude_check_holds_for_two_nodes_and_at_its_tolerance() -> None:
    """A two-node table refuses an amplitude beyond it too; an amplitude up to 1e-12 m beyond the shorter
    side is accepted (round-off; the arcsine mass beyond the table, ~2e-6, is then left out), 3e-12 m is not."""
    with pytest.raises(ValueError, match="exceeds"):
        oscillation_weights(np.array([-0.02, 0.02]), 0.03)
    nodes = np.linspace(-0.05, 0.05, 5)
    assert oscillation_weights(nodes, 0.05 + 1e-12).sum() == pytest.approx(1.0, abs=1e-5)
    with pytest.raises(ValueError, match="exceeds"):
        oscillation_weights(nodes, 0.05 + 3e-12)


def test_a_motion_of_any_non_zero_amplitude_moves() -> None:
    """Only a disabled spec or a zero amplitude holds the specimen: 1 m (a furnace with a long travel, its
    limits checked elsewhere) is a sine like any other amplitude."""
    from twin.physics.motion import eta_function

    spec = OscillationSpec.model_construct(enabled=True, amplitude=1.0, period=4.0)
    assert eta_function(spec)(1.0) == pytest.approx(1.0, rel=1e-12)
    assert eta_function(spec)(3.0) == pytest.approx(-1.0, rel=1e-12)
