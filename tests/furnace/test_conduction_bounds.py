"""The conduction operator's Gershgorin bound (``ConductionOperator.max_row_sum``), which sets the plant's
explicit substeps (``Plant.spectral_radius_bound``): a true bound of the row sums of |d heat_flow / dT| over
every field in [T_min, T_max], and no looser than its docstring says.

Oracles: the row sums of the analytic Jacobian (itself checked against finite differences in
test_plant_conduction.py) on adversarial fields (checkerboards of T_min and T_max where the conductivity is
largest and steepest, edge cells far from their ambient), and on a uniform field at the table's largest
conductivity with insulated edges, where the bound's conduction term is attained exactly: every interior
cell's row is 2 sum_faces g lambda.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated.conduction import ConductionOperator, EdgeExchange
from twin.physics.materials import Steel


@pytest.fixture(scope="module")
def cfg():
    return small_config()


def _robin(cfg) -> EdgeExchange:
    # holders hot and cold, gas at a profile: the ambient range 350..900 K (the plant's own values are similar)
    nx = cfg.specimen.nx
    return EdgeExchange(alpha_x0=400.0, T_x0=900.0, alpha_xL=250.0, T_xL=350.0, alpha_y=30.0,
                        T_y=np.linspace(400.0, 800.0, nx))


def _row_sums(op: ConductionOperator, T: np.ndarray) -> np.ndarray:
    J = op.jacobian(T).toarray()
    return np.abs(J).sum(axis=1)


def _checkerboard(op: ConductionOperator, lo: float, hi: float, flip: bool = False) -> np.ndarray:
    i, j = np.meshgrid(np.arange(op.nx), np.arange(op.ny))
    odd = ((i + j) % 2 == 1) ^ flip
    return np.where(odd, hi, lo).ravel().astype(float)


@pytest.mark.parametrize("lo, hi", [(300.0, 300.0), (300.0, 400.0), (300.0, 1300.0), (950.0, 1100.0),
                                    (1040.0, 1045.0)])
def test_the_bound_covers_every_row_of_adversarial_fields(cfg, lo, hi) -> None:
    op = ConductionOperator.for_plate(cfg, Steel.from_config(cfg), _robin(cfg))
    bound = op.max_row_sum(lo, hi)
    rng = np.random.default_rng(5)
    fields = [_checkerboard(op, lo, hi), _checkerboard(op, lo, hi, flip=True), np.full(op.n, lo),
              np.full(op.n, hi), rng.uniform(lo, hi, op.n)]
    worst = max(float(_row_sums(op, T).max()) for T in fields)
    assert worst <= bound * (1 + 1e-12), (lo, hi, worst, bound)
    # not a vacuous bound: within a factor 3 of the worst row found (the slope and edge terms take the
    # largest slope with the largest difference at once, which no single field has)
    assert bound <= 3.0 * worst, (lo, hi, worst, bound)


def test_on_a_uniform_field_at_the_largest_conductivity_the_conduction_term_is_attained(cfg) -> None:
    steel = Steel.from_config(cfg)
    op = ConductionOperator.for_plate(cfg, steel, EdgeExchange.insulated(cfg))
    k = int(np.argmax(steel.conductivity_table))
    T_max_lambda = float(steel.temperatures[k])
    rows = _row_sums(op, np.full(op.n, T_max_lambda))
    assert op.max_row_sum(T_max_lambda, T_max_lambda) == pytest.approx(float(rows.max()), rel=1e-12)
    # an interior cell: four faces, each g = B_s * face / distance; its row is 2 lambda sum g
    s = cfg.specimen
    dx, dy = s.length / s.nx, s.width / s.ny
    interior = 2.0 * steel.conductivity_table[k] * s.thickness * 2.0 * (dy / dx + dx / dy)
    assert float(rows.max()) == pytest.approx(interior, rel=1e-12)


def test_the_slope_and_edge_terms_are_those_of_the_docstring(cfg) -> None:
    # lambda_max + slope_max (T_max - T_min) / 2 on the row geometry, plus the edge faces' alpha B_s s with the
    # lambda' term at the largest difference between an edge cell and its ambient
    steel = Steel.from_config(cfg)
    insulated = ConductionOperator.for_plate(cfg, steel, EdgeExchange.insulated(cfg))
    lam, temps = np.asarray(steel.conductivity_table), np.asarray(steel.temperatures)
    slope = float(np.max(np.abs(np.diff(lam) / np.diff(temps))))
    base = insulated.max_row_sum(600.0, 600.0) / float(lam.max())  # the row geometry, 2 sum g (m)
    for lo, hi in ((600.0, 900.0), (300.0, 1300.0)):
        assert insulated.max_row_sum(lo, hi) == pytest.approx(base * (lam.max() + 0.5 * slope * (hi - lo)), rel=1e-12)
    robin = ConductionOperator.for_plate(cfg, steel, _robin(cfg))
    s = cfg.specimen
    dx, dy = s.length / s.nx, s.width / s.ny
    # the corner cell at x = 0 carries the holder face (alpha 400, side dy) and a gas face (alpha 30, side dx)
    ga_corner = 400.0 * s.thickness * dy + 30.0 * s.thickness * dx
    r_max = max(400.0 * dx / 2, 250.0 * dx / 2, 30.0 * dy / 2)
    for lo, hi in ((600.0, 900.0), (300.0, 1300.0)):
        d_edge = max(abs(hi - 350.0), abs(lo - 900.0))
        want = base * (lam.max() + 0.5 * slope * (hi - lo)) + ga_corner * (1 + r_max * slope * d_edge / lam.min() ** 2)
        assert robin.max_row_sum(lo, hi) == pytest.approx(want, rel=1e-12)
