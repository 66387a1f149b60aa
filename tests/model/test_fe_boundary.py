"""Shared Newton-cooling losses (twin.physics.boundary, paper eqs. 3 and 6) against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import load_config
from twin.physics.boundary import (
    clamped_fraction,
    edge_losses,
    face_loss_coefficients,
    holder_temperature,
    inert_gas_temperature,
)

CFG = load_config()  # default furnace: L_s = 0.4 m, 26 x 17 cells, clamp 20 mm


def test_inert_gas_profile_is_linear_between_top_and_bottom() -> None:
    g, L = CFG.inert_gas, CFG.specimen.length
    T = inert_gas_temperature(CFG, [0.0, L / 4, L])
    np.testing.assert_allclose(
        T, [g.temperature_top, 0.75 * g.temperature_top + 0.25 * g.temperature_bottom, g.temperature_bottom], rtol=1e-15
    )


def test_clamped_area_equals_the_two_jaws() -> None:
    s = CFG.specimen
    f = clamped_fraction(CFG)
    cell_area = s.length * s.width / s.n_states
    # two jaws of clamp_length x W_s, exactly (fractions of partly clamped cells included)
    assert f.sum() * cell_area == pytest.approx(2 * CFG.holders.clamp_length * s.width, rel=1e-12)
    # default: dx = 0.4 / 26 = 15.4 mm < clamp 20 mm < 2 dx: first column fully, second partly clamped
    dx, lc = s.length / s.nx, CFG.holders.clamp_length
    assert dx < lc < 2 * dx
    row = f[: s.nx]
    assert row[0] == 1.0 and row[-1] == 1.0
    assert row[1] == pytest.approx((lc - dx) / dx, rel=1e-12)
    assert (row[2:-2] == 0.0).all()


def test_face_loss_coefficients_by_hand() -> None:
    s, h, g = CFG.specimen, CFG.holders, CFG.inert_gas
    d, b = face_loss_coefficients(CFG)
    # fully clamped top cell: both faces against the upper jaw
    assert d[0] == pytest.approx(2 * h.alpha, rel=1e-15)
    assert b[0] == pytest.approx(2 * h.alpha * h.temperature_upper, rel=1e-15)
    # free cell i = 13 (x = 13.5 dx) in row j = 8: both faces in the gas at T_ig(x)
    k = 13 + s.nx * 8
    x = 13.5 * s.length / s.nx
    assert d[k] == pytest.approx(2 * g.alpha, rel=1e-15)
    assert b[k] == pytest.approx(2 * g.alpha * inert_gas_temperature(CFG, x), rel=1e-15)
    # fully clamped bottom cell at the lower jaw; alpha_scale scales both coefficients
    d2, b2 = face_loss_coefficients(CFG, alpha_scale=1.5)
    assert b[s.nx - 1] == pytest.approx(2 * h.alpha * h.temperature_lower, rel=1e-15)
    np.testing.assert_allclose(d2, 1.5 * d, rtol=1e-15)
    np.testing.assert_allclose(b2, 1.5 * b, rtol=1e-15)
    assert holder_temperature(CFG, 0.1) == h.temperature_upper
    assert holder_temperature(CFG, 0.3) == h.temperature_lower


def test_edge_losses() -> None:
    e = edge_losses(CFG, alpha_scale=2.0)
    assert (e.alpha_x, e.alpha_y) == (2 * CFG.holders.alpha, 2 * CFG.inert_gas.alpha)
    assert (e.T_top, e.T_bottom) == (CFG.holders.temperature_upper, CFG.holders.temperature_lower)
