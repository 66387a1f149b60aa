"""The fillet (paper section 3.1) is defined once (twin.physics.fillet) and used everywhere.

The fillet mean is the area integral of the cell field over 0.25-0.75 L_s x 0.2-0.8 W_s divided by
its area, a border cell counting by its area inside (product.md).  The oracle below computes the
area of every cell inside the fillet with explicit loops over the cells' corners, independently
of the vectorised overlap in the code.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from twin.config import load_config, small_config
from twin.furnace.simulated.plant import Plant
from twin.model.fe import FEModel
from twin.physics.fillet import Fillet
from twin.runs.metrics import compute_metrics

AGREE = 1e-9  # K: the same quantity computed by every user of the fillet (issue: "agree to 1e-9")


def _oracle_mean(cfg, T: np.ndarray) -> float:
    s = cfg.specimen
    x0, x1, y0, y1 = 0.25 * s.length, 0.75 * s.length, 0.2 * s.width, 0.8 * s.width
    dx, dy = s.length / s.nx, s.width / s.ny
    total = area = 0.0
    for j in range(s.ny):
        for i in range(s.nx):
            ax = max(0.0, min(x1, (i + 1) * dx) - max(x0, i * dx))
            ay = max(0.0, min(y1, (j + 1) * dy) - max(y0, j * dy))
            total += ax * ay * T[i + s.nx * j]
            area += ax * ay
    assert area == pytest.approx((x1 - x0) * (y1 - y0), rel=1e-12)
    return total / area


@pytest.mark.parametrize("cfg", [load_config(), small_config()], ids=["default", "small"])
def test_every_user_of_the_fillet_mean_agrees_on_a_random_field(cfg) -> None:
    rng = np.random.default_rng(7)
    T = rng.uniform(300.0, 1300.0, cfg.specimen.n_states)
    expected = _oracle_mean(cfg, T)
    fillet = Fillet.of(cfg)
    s = cfg.specimen
    # the plant helpers (steady powers, open-loop runs)
    assert Plant(cfg, None).fillet_mean(T) == pytest.approx(expected, abs=AGREE)
    # the grid form and the flat form
    assert fillet.mean(T.reshape(s.ny, s.nx)) == pytest.approx(expected, abs=AGREE)
    # the run metrics, from a stored series whose true field is T and whose reference is 0 K (scale 1 K)
    x, y = (np.arange(s.nx) + 0.5) * s.length / s.nx, (np.arange(s.ny) + 0.5) * s.width / s.ny
    t = np.linspace(0.0, 2.0, 21)
    ts = dict(t=t, T_ref=np.zeros_like(t), T_mean_hat=np.zeros_like(t), tc=np.zeros((21, 4)),
              tc_hat=np.zeros((21, 4)), t_field=t, field_hat=np.zeros((21, s.ny, s.nx)),
              field_true=np.broadcast_to(T.reshape(s.ny, s.nx), (21, s.ny, s.nx)), x=x, y=y,
              L_s=s.length, W_s=s.width, t_E=1.0, setpoint=1.0)
    assert compute_metrics(ts)["true_mean_error_steady_max"] == pytest.approx(abs(expected), abs=AGREE)
    # the estimator's c_m: the same functional of the model's field on the cells
    fe = FEModel(cfg)
    theta = rng.uniform(300.0, 1300.0, fe.n)
    assert fe.c_m @ theta == pytest.approx(_oracle_mean(cfg, fe.M_theta @ theta), abs=AGREE)
    assert fe.fillet_mean(theta) == pytest.approx(fillet.mean(fe.field_on_cells(theta)), abs=AGREE)


def test_cells_on_the_border_count_by_their_area_inside() -> None:
    cfg = load_config()  # 26 x 17: the centres of cells 6 and 19 lie exactly on 0.25 / 0.75 L_s
    fillet = Fillet.of(cfg)
    w = fillet.weights / fillet.weights.max()
    assert w[8, 6] == pytest.approx(0.5) and w[8, 19] == pytest.approx(0.5)  # half of the cell inside
    assert w[3, 13] == pytest.approx(0.6) and w[13, 13] == pytest.approx(0.6)  # 0.2 W_s = 3.4 cells
    assert w[2, 13] == 0.0 and w[8, 5] == 0.0
    # T_sup takes the cells whose centres lie in the closed fillet: 14 columns (6..19) x 11 rows (3..13)
    assert int(fillet.mask.sum()) == 154 and fillet.mask[8, 6] and fillet.mask[8, 19] and not fillet.mask[8, 20]


def test_sup_and_spread() -> None:
    cfg = small_config()
    fillet = Fillet.of(cfg)
    s = cfg.specimen
    field = np.full((s.ny, s.nx), 1000.0)
    field[8, 13] += 44.0  # a hot spot in the middle
    field[0, 0] += 500.0  # outside the fillet: ignored
    assert fillet.sup(field, 1000.0) == pytest.approx(44.0)
    assert fillet.sup(np.stack([field, field - 10.0]), np.array([1000.0, 1000.0])).tolist() == pytest.approx(
        [44.0, 34.0])
    assert fillet.spread(field) == pytest.approx(44.0 - 44.0 * fillet.weights[8, 13], rel=1e-12)
    with pytest.raises(ValueError, match="does not fit"):
        fillet.mean(np.zeros((3, 3)))


# ------------------------------------------------------------------ properties (hypothesis)
from hypothesis import given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra.numpy import arrays  # noqa: E402


@st.composite
def _grids_and_fields(draw):
    nx, ny = draw(st.integers(2, 30)), draw(st.integers(2, 20))
    L, W = draw(st.floats(0.05, 2.0)), draw(st.floats(0.05, 2.0))
    field = lambda: draw(arrays(float, (ny, nx), elements=st.floats(-1e3, 2e3)))  # noqa: E731
    return nx, ny, L, W, field(), field(), draw(st.floats(-3.0, 3.0)), draw(st.floats(-3.0, 3.0))


def _fillet(nx, ny, L, W):
    return Fillet.on_grid((np.arange(nx) + 0.5) * L / nx, (np.arange(ny) + 0.5) * W / ny, L, W)


@given(_grids_and_fields())
def test_fillet_mean_is_linear_bounded_and_the_area_integral(case) -> None:
    nx, ny, L, W, F, G, a, b = case
    fillet = _fillet(nx, ny, L, W)
    scale = 1e-12 * (np.abs(F).max() + np.abs(G).max() + 1.0)
    assert fillet.mean(a * F + b * G) == pytest.approx(a * fillet.mean(F) + b * fillet.mean(G), abs=10 * scale)
    # bounded by the extremes of the cells that overlap the fillet (a convex combination of them)
    inside = F[fillet.weights > 0]
    assert inside.min() - scale <= fillet.mean(F) <= inside.max() + scale
    # the area integral of the cell-wise constant field over the fillet, divided by its area
    cfg = SimpleNamespace(specimen=SimpleNamespace(length=L, width=W, nx=nx, ny=ny))
    assert fillet.mean(F) == pytest.approx(_oracle_mean(cfg, F.ravel()), abs=10 * scale)
    # a constant field is its own mean; T_sup of a field against itself is 0
    assert fillet.mean(np.full((ny, nx), 812.5)) == pytest.approx(812.5, rel=1e-14)
    assert fillet.sup(F, fillet.mean(F)) == fillet.spread(F)


def test_batches_of_flat_fields() -> None:
    cfg = small_config()
    fillet = Fillet.of(cfg)
    rng = np.random.default_rng(2)
    T = rng.uniform(500.0, 900.0, (3, cfg.specimen.n_states))  # three fields in the state order (..., N_s)
    np.testing.assert_allclose(fillet.mean(T), [_oracle_mean(cfg, row) for row in T], rtol=1e-13)
    np.testing.assert_allclose(fillet.sup(T, np.array([600.0, 700.0, 800.0])),
                               [fillet.sup(row, ref) for row, ref in zip(T, (600.0, 700.0, 800.0), strict=True)])


def test_the_fillet_does_not_depend_on_the_unit_of_length() -> None:
    """Weights and mask depend on x / L_s and y / W_s only: the 26 x 17 grid, whose centres 6 and 19 lie on
    the fillet's edges 0.25 / 0.75 L_s, gives the same fillet in um, mm, m and km (the edge tolerance scales
    with the specimen; a fixed or inverted one takes in every cell or misses the edge cells)."""
    ref = _fillet(26, 17, 0.52, 0.34)
    assert int(ref.mask.sum()) == 154  # the edge cells are in
    for scale in (1e-6, 1e-3, 1e3, 1e6):
        f = _fillet(26, 17, 0.52 * scale, 0.34 * scale)
        np.testing.assert_array_equal(f.mask, ref.mask, err_msg=f"scale {scale}")
        np.testing.assert_allclose(f.weights, ref.weights, rtol=1e-12, atol=1e-15, err_msg=f"scale {scale}")


def test_centres_in_single_precision_are_taken_at_their_values() -> None:
    """Cell centres given as float32 give the fillet of their (exact) double values: the overlaps are
    computed in double precision (in float32 the weights would be rounded to ~1e-7)."""
    x = ((np.arange(26) + 0.5) * 0.52 / 26).astype(np.float32)
    y = ((np.arange(17) + 0.5) * 0.34 / 17).astype(np.float32)
    single, double = Fillet.on_grid(x, y, 0.52, 0.34), Fillet.on_grid(x.astype(float), y.astype(float), 0.52, 0.34)
    np.testing.assert_array_equal(single.weights, double.weights)
    np.testing.assert_array_equal(single.mask, double.mask)


def test_the_closed_fillet_takes_centres_up_to_its_tolerance_and_no_further() -> None:
    """T_sup's cells: centres in the closed fillet, its edges widened by 1e-12 L_s (W_s) against round-off.
    A centre exactly at an edge +- that tolerance is in, one at three times the tolerance is out."""
    L, W = 0.52, 0.34
    ex, ey = 1e-12 * L, 1e-12 * W
    x = np.array([0.25 * L - ex, 0.25 * L - 3 * ex, 0.5 * L, 0.75 * L + 3 * ex, 0.75 * L + ex])
    y = np.array([0.2 * W - ey, 0.2 * W - 3 * ey, 0.5 * W, 0.8 * W + 3 * ey, 0.8 * W + ey])
    mask = Fillet.on_grid(x, y, L, W).mask
    inside = np.array([True, False, True, False, True])
    np.testing.assert_array_equal(mask, np.outer(inside, inside))
