"""Thermocouples: bilinear interpolation of the cell-centred field plus seeded Gaussian noise."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated.thermocouples import Thermocouples
from twin.physics.motion import eta_function
from twin.scenario import OscillationSpec


def _centres(cfg):
    s = cfg.specimen
    x = (np.arange(s.nx) + 0.5) * s.length / s.nx
    y = (np.arange(s.ny) + 0.5) * s.width / s.ny
    return x, y


def test_bilinear_field_is_reproduced_exactly_inside_the_centre_hull():
    cfg = small_config()
    s = cfg.specimen
    x, y = _centres(cfg)
    X, Y = np.meshgrid(x, y)

    def f(px, py):  # bilinear: interpolation must be exact (oracle: the function itself)
        return 700.0 + 900.0 * px + 400.0 * py + 5000.0 * px * py

    T = f(X, Y).ravel()
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(x[0], x[-1], 50), rng.uniform(y[0], y[-1], 50)])
    tcs = Thermocouples(cfg, pts)
    np.testing.assert_allclose(tcs.read(T, rng, noise=0.0), f(pts[:, 0], pts[:, 1]), rtol=1e-12)
    # the paper's TC positions too
    tcs = Thermocouples(cfg, cfg.tc_positions())
    P = np.array(cfg.tc_positions())
    np.testing.assert_allclose(tcs.true_values(T), f(P[:, 0], P[:, 1]), rtol=1e-12)
    assert s.n_states == T.size


def test_at_a_cell_centre_the_reading_is_that_cell():
    cfg = small_config()
    x, y = _centres(cfg)
    T = np.arange(cfg.specimen.n_states, dtype=float)
    tcs = Thermocouples(cfg, [(x[3], y[5]), (x[-1], y[0])])
    np.testing.assert_allclose(tcs.true_values(T), [3 + cfg.specimen.nx * 5, cfg.specimen.nx - 1])


def test_edges_hold_the_outermost_centre_values():
    cfg = small_config()
    s = cfg.specimen
    x, y = _centres(cfg)
    T = np.random.default_rng(1).uniform(300, 1000, s.n_states)
    F = T.reshape(s.ny, s.nx)
    tcs = Thermocouples(cfg, [(0.0, 0.0), (s.length, s.width), (0.0, y[4])])
    np.testing.assert_allclose(tcs.true_values(T), [F[0, 0], F[-1, -1], F[4, 0]])


def test_noise_is_seeded_and_has_the_given_spread():
    cfg = small_config()
    T = np.full(cfg.specimen.n_states, 1000.0)
    tcs = Thermocouples(cfg, [(0.2, 0.1)] * 4000)
    a = tcs.read(T, np.random.default_rng(7), noise=2.0)
    b = tcs.read(T, np.random.default_rng(7), noise=2.0)
    np.testing.assert_array_equal(a, b)
    # 4000 samples: the sample std of N(0, 2^2) has standard error 2 / sqrt(8000) ~ 0.022;
    # 0.1 K is > 4 standard errors; the mean's standard error is 2 / sqrt(4000) ~ 0.032 -> 0.15 K
    assert abs(np.std(a - 1000.0) - 2.0) < 0.1
    assert abs(np.mean(a - 1000.0)) < 0.15


def test_readings_are_the_field_plus_noise_times_standard_normal_draws():
    """y = H T + noise * N(0, 1) with the generator's own draws, in order; no noise: no draw at all."""
    cfg = small_config()
    T = np.random.default_rng(3).uniform(600.0, 1000.0, cfg.specimen.n_states)
    tcs = Thermocouples(cfg, cfg.tc_positions())
    exact = tcs.true_values(T)
    got = tcs.read(T, np.random.default_rng(11), noise=0.5)
    np.testing.assert_allclose(got, exact + 0.5 * np.random.default_rng(11).standard_normal(4), rtol=1e-15)
    rng = np.random.default_rng(11)
    np.testing.assert_array_equal(tcs.read(T, rng, noise=0.0), exact)
    # the generator was not touched: the noise of the next reading does not depend on noise-free reads
    assert rng.standard_normal() == np.random.default_rng(11).standard_normal()
    assert tcs.positions.shape == (4, 2)


def test_outside_the_plate_is_an_error():
    cfg = small_config()
    with pytest.raises(ValueError, match="outside"):
        Thermocouples(cfg, [(cfg.specimen.length + 0.01, 0.1)])


def test_eta_function():
    spec = OscillationSpec(enabled=True, amplitude=0.048, period=18.0)
    eta = eta_function(spec)
    t = np.linspace(0, 36, 1001)
    vals = np.array([eta(v) for v in t])
    np.testing.assert_allclose(vals, 0.048 * np.sin(2 * np.pi * t / 18.0), atol=1e-15)
    assert eta_function(OscillationSpec(enabled=False))(3.0) == 0.0
    # a later start t0 begins at eta = 0
    assert eta_function(spec, t0=5.0)(5.0) == 0.0


def test_positions_are_a_float_array_also_for_integer_input():
    """``positions`` (the Furnace protocol's tc_positions) is the (n, 2) float64 array in m whatever sequence
    was given: integer coordinates (a corner at (0, 0)) stay floats for the run files and the views."""
    cfg = small_config()
    tcs = Thermocouples(cfg, [(0, 0), [0, 0]])
    assert tcs.positions.dtype == np.float64 and tcs.positions.shape == (2, 2)
    assert tcs.positions.tolist() == [[0.0, 0.0], [0.0, 0.0]]
