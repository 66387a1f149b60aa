"""FE matrices of twin.model.fe against independent oracles (paper eqs. 7-10, 19, 21).

Oracles: (a) textbook element matrices of the bilinear rectangle, assembled in a loop here;
(b) bilinear fields f(x, y) = a + b x + c y + e x y, which the trial space (7) represents
exactly, integrated with *global* Gauss-Legendre rules (exact for the low-degree polynomials
involved, independent of the piecewise quadrature inside twin.model.fe); (c) scipy's
RegularGridInterpolator for piecewise-bilinear fields.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from twin.config import small_config
from twin.model.fe import FEModel
from twin.physics.boundary import inert_gas_temperature
from twin.physics.fillet import fillet_box

# Every exact identity below is checked to 1e-10 relative: the quantities are sums of ~10^2
# products of O(1) numbers, so double-precision rounding stays near 1e-14; 1e-10 leaves margin.
EXACT = 1e-10


@pytest.fixture(scope="module")
def fe() -> FEModel:
    return FEModel(small_config())


def _gauss_2d(x0: float, x1: float, y0: float, y1: float, n: int = 4):
    g, w = np.polynomial.legendre.leggauss(n)
    xs = 0.5 * (x1 + x0) + 0.5 * (x1 - x0) * g
    ys = 0.5 * (y1 + y0) + 0.5 * (y1 - y0) * g
    X, Y = np.meshgrid(xs, ys)
    Wt = np.outer(w, w) * 0.25 * (x1 - x0) * (y1 - y0)
    return X, Y, Wt


def _gauss_1d(a: float, b: float, n: int = 4):
    g, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (a + b) + 0.5 * (b - a) * g, 0.5 * (b - a) * w


def _bilinear(coef):
    a, b, c, e = coef
    return lambda x, y: a + b * x + c * y + e * x * y


def _nodal(fe: FEModel, f) -> np.ndarray:
    nodes = fe.nodes()
    return f(nodes[:, 0], nodes[:, 1])


F_COEF = (900.0, 300.0, -500.0, 2000.0)  # K, K/m, K/m, K/m^2: a few hundred K over the plate
G_COEF = (1.0, -2.0, 4.0, 7.0)


def test_interpolation_is_exact_for_bilinear_fields(fe: FEModel) -> None:
    f = _bilinear(F_COEF)
    rng = np.random.default_rng(1)
    s = fe.cfg.specimen
    pts = rng.uniform([0, 0], [s.length, s.width], size=(200, 2))
    np.testing.assert_allclose(fe.phi(pts) @ _nodal(fe, f), f(pts[:, 0], pts[:, 1]), rtol=EXACT)
    np.testing.assert_allclose(fe.phi(pts).sum(axis=1), 1.0, rtol=EXACT)


def _textbook_assembly(fe: FEModel) -> tuple[np.ndarray, np.ndarray]:
    """Consistent mass and Laplace stiffness of bilinear rectangles (e.g. Reddy, FEM, ch. 8)."""
    me = np.array([[4, 2, 1, 2], [2, 4, 2, 1], [1, 2, 4, 2], [2, 1, 2, 4]], float) / 36.0
    kx = np.array([[2, -2, -1, 1], [-2, 2, 1, -1], [-1, 1, 2, -2], [1, -1, -2, 2]], float) / 6.0
    ky = np.array([[2, 1, -1, -2], [1, 2, -2, -1], [-1, -2, 2, 1], [-2, -1, 1, 2]], float) / 6.0
    nx = fe.nx_nodes
    M = np.zeros((fe.n, fe.n))
    K = np.zeros((fe.n, fe.n))
    for j in range(fe.ny_nodes - 1):
        for i in range(nx - 1):
            a = fe.x_nodes[i + 1] - fe.x_nodes[i]
            b = fe.y_nodes[j + 1] - fe.y_nodes[j]
            idx = [i + nx * j, i + 1 + nx * j, i + 1 + nx * (j + 1), i + nx * (j + 1)]  # counter-clockwise
            M[np.ix_(idx, idx)] += a * b * me
            K[np.ix_(idx, idx)] += (b / a) * kx + (a / b) * ky
    return M, K


def test_mass_and_stiffness_match_textbook_element_matrices(fe: FEModel) -> None:
    M_ref, K_ref = _textbook_assembly(fe)
    np.testing.assert_allclose(fe.M, fe.heat_capacity * M_ref, rtol=EXACT, atol=EXACT * np.abs(fe.M).max())
    np.testing.assert_allclose(fe.K, -fe.conductivity * K_ref, rtol=EXACT, atol=EXACT * np.abs(fe.K).max())


def test_constant_properties_come_from_the_material_table(fe: FEModel) -> None:
    # enthalpy-equivalent c_p over [300, 1100] K and lambda(1100 K) = 29.0 W/(m K), furnace.md table
    cfg = fe.cfg
    T = np.linspace(*cfg.fe.capacity_range, 200001)
    cp = np.interp(T, cfg.material.temperatures, cfg.material.heat_capacity)
    # trapezoid on 200001 points of a piecewise-linear c_p: error below 1e-6 J/(kg K)
    assert fe.heat_capacity == pytest.approx(np.trapezoid(cp, T) / (T[-1] - T[0]), abs=1e-6)
    assert fe.conductivity == pytest.approx(29.0, abs=1e-12)


def test_quadratic_forms_of_bilinear_fields(fe: FEModel) -> None:
    s = fe.cfg.specimen
    f, g = _bilinear(F_COEF), _bilinear(G_COEF)
    tf, tg = _nodal(fe, f), _nodal(fe, g)
    X, Y, Wt = _gauss_2d(0.0, s.length, 0.0, s.width)
    mass = fe.heat_capacity * np.sum(Wt * f(X, Y) * g(X, Y))
    # grad f . grad g for the bilinear fields, integrated exactly (degree <= 2 in each variable)
    a, b, c, e = F_COEF
    a2, b2, c2, e2 = G_COEF
    grad = (b + e * Y) * (b2 + e2 * Y) + (c + e * X) * (c2 + e2 * X)
    stiff = -fe.conductivity * np.sum(Wt * grad)
    assert tg @ fe.M @ tf == pytest.approx(mass, rel=EXACT)
    assert tg @ fe.K @ tf == pytest.approx(stiff, rel=EXACT)
    np.testing.assert_allclose(np.ones(fe.n) @ fe.K, 0.0, atol=EXACT * np.abs(fe.K).max())


def test_fillet_mean_and_inhomogeneity(fe: FEModel) -> None:
    f = _bilinear(F_COEF)
    tf = _nodal(fe, f)
    x0, x1, y0, y1 = fillet_box(fe.cfg.specimen.length, fe.cfg.specimen.width)
    X, Y, Wt = _gauss_2d(x0, x1, y0, y1)
    area = (x1 - x0) * (y1 - y0)
    mean = np.sum(Wt * f(X, Y)) / area
    var = np.sum(Wt * (f(X, Y) - mean) ** 2) / area
    assert fe.c_m_exact @ tf == pytest.approx(mean, rel=EXACT)
    assert tf @ fe.W @ tf == pytest.approx(var, rel=1e-8)  # var ~ 1e3 K^2 from differences of ~1e6 K^2
    np.testing.assert_allclose(fe.W @ np.ones(fe.n), 0.0, atol=1e-14)


def test_fillet_mean_of_a_piecewise_bilinear_field(fe: FEModel) -> None:
    rng = np.random.default_rng(2)
    theta = rng.uniform(800.0, 1200.0, fe.n)
    interp = RegularGridInterpolator((fe.y_nodes, fe.x_nodes), theta.reshape(fe.ny_nodes, fe.nx_nodes))
    x0, x1, y0, y1 = fillet_box(fe.cfg.specimen.length, fe.cfg.specimen.width)
    n = 1200  # midpoint rule: exact on the bilinear pieces; only cells cut by node lines err
    xs = x0 + (np.arange(n) + 0.5) * (x1 - x0) / n
    ys = y0 + (np.arange(n) + 0.5) * (y1 - y0) / n
    X, Y = np.meshgrid(xs, ys)
    vals = interp(np.column_stack([Y.ravel(), X.ravel()]))
    # error bound: (cut cells / all cells ~ 10 / 1200) x (h / 2)^2-scale kink error ~ 1e-6 of 400 K span
    assert fe.c_m_exact @ theta == pytest.approx(vals.mean(), abs=1e-3)
    assert theta @ fe.W @ theta == pytest.approx(vals.var(), rel=1e-4)


def test_cell_projection_and_mapping(fe: FEModel) -> None:
    s = fe.cfg.specimen
    f = _bilinear(F_COEF)
    tf = _nodal(fe, f)
    dx, dy = s.length / s.nx, s.width / s.ny
    cell_int = np.empty(s.nx * s.ny)
    centres = np.empty((s.nx * s.ny, 2))
    for j in range(s.ny):
        for i in range(s.nx):
            X, Y, Wt = _gauss_2d(i * dx, (i + 1) * dx, j * dy, (j + 1) * dy, n=2)
            cell_int[i + s.nx * j] = np.sum(Wt * f(X, Y))
            centres[i + s.nx * j] = ((i + 0.5) * dx, (j + 0.5) * dy)
    np.testing.assert_allclose(fe.G @ tf, cell_int, rtol=EXACT)
    np.testing.assert_allclose(fe.M_theta @ tf, f(centres[:, 0], centres[:, 1]), rtol=EXACT)
    np.testing.assert_allclose(fe.field_on_cells(tf).ravel(), fe.M_theta @ tf, rtol=EXACT)  # tensor form, same values


def test_edge_terms_match_the_boundary_conditions(fe: FEModel) -> None:
    cfg = fe.cfg
    s, h, ig = cfg.specimen, cfg.holders, cfg.inert_gas
    f, g = _bilinear(F_COEF), _bilinear(G_COEF)
    tf, tg = _nodal(fe, f), _nodal(fe, g)
    ys, wy = _gauss_1d(0.0, s.width)
    xs, wx = _gauss_1d(0.0, s.length)
    T_ig = inert_gas_temperature(cfg, xs)
    # g-weighted edge losses of (3a-d): int g alpha (f - T_env) ds over the four edges
    loss = h.alpha * np.sum(wy * g(0.0, ys) * (f(0.0, ys) - h.temperature_upper))
    loss += h.alpha * np.sum(wy * g(s.length, ys) * (f(s.length, ys) - h.temperature_lower))
    loss += ig.alpha * np.sum(wx * g(xs, 0.0) * (f(xs, 0.0) - T_ig))
    loss += ig.alpha * np.sum(wx * g(xs, s.width) * (f(xs, s.width) - T_ig))
    assert tg @ fe.gamma(tf) == pytest.approx(-loss, rel=EXACT)


def test_hat_functions_vanish_outside_the_mesh() -> None:
    from twin.model.fe import hat_functions

    nodes = np.array([0.0, 0.1, 0.3])
    np.testing.assert_array_equal(hat_functions(nodes, [-0.05, 0.35]), np.zeros((2, 3)))  # documented: zero outside
    np.testing.assert_allclose(hat_functions(nodes, [0.0, 0.2, 0.3]), [[1, 0, 0], [0, 0.5, 0.5], [0, 0, 1]])
