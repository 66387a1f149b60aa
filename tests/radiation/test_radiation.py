"""Exchange factors and net-radiation matrices (paper eqs. 4-5) against independent oracles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.config import STEFAN_BOLTZMANN, small_config
from twin.physics.geometry import build_enclosure, furnace_geometry, rectangle
from twin.radiation.net_radiation import net_radiation_matrix
from twin.radiation.raytrace import trace_exchange_factors
from twin.radiation.reciprocity import enforce_reciprocity_closure


def parallel_rectangles(a: float, b: float, c: float) -> float:
    """Howell's catalogue C-11: directly opposed parallel rectangles a x b at distance c."""
    X, Y = a / c, b / c
    t = 0.5 * math.log((1 + X**2) * (1 + Y**2) / (1 + X**2 + Y**2))
    t += X * math.sqrt(1 + Y**2) * math.atan(X / math.sqrt(1 + Y**2))
    t += Y * math.sqrt(1 + X**2) * math.atan(Y / math.sqrt(1 + X**2))
    t -= X * math.atan(X) + Y * math.atan(Y)
    return 2 * t / (math.pi * X * Y)


def perpendicular_rectangles(l: float, w: float, h: float) -> float:
    """Howell's catalogue C-14: F from rectangle l x w to l x h, perpendicular, common edge l."""
    H, W = h / l, w / l
    HW = H * H + W * W
    a = W * math.atan(1 / W) + H * math.atan(1 / H) - math.sqrt(HW) * math.atan(1 / math.sqrt(HW))
    g1 = (1 + W * W) * (1 + H * H) / (1 + HW)
    g2 = (W * W * (1 + HW) / ((1 + W * W) * HW)) ** (W * W)
    g3 = (H * H * (1 + HW) / ((1 + H * H) * HW)) ** (H * H)
    return (a + 0.25 * math.log(g1 * g2 * g3)) / (math.pi * W)


def test_howell_formulas_reproduce_tabulated_values():
    # Howell's catalogue / Incropera Fig. 13.4-13.6: unit squares at unit distance 0.1998,
    # perpendicular unit squares 0.2000
    assert parallel_rectangles(1, 1, 1) == pytest.approx(0.1998, abs=1e-4)
    assert perpendicular_rectangles(1, 1, 1) == pytest.approx(0.2000, abs=1e-4)


def _view_factor(parts, n_rays: int, seed: int, qmc: bool = True) -> float:
    enc = build_enclosure(parts, np.zeros(2))
    F, stats = trace_exchange_factors(
        enc, np.array([n_rays, 10]), max_bounces=0, min_weight=0.01, rng=np.random.default_rng(seed), qmc=qmc
    )
    return float(F[0, 1])


@pytest.mark.parametrize("qmc", [True, False])
@pytest.mark.parametrize("a,b,c", [(1.0, 1.0, 1.0), (0.2, 0.2, 0.05)])
def test_parallel_squares_view_factor(a, b, c, qmc):
    # 400k rays: binomial std sqrt(F(1-F)/N) <= 0.1 % relative for F >= 0.2, so 1 % is > 5 sigma
    # (plain Monte Carlo; the quasi-random estimate has a smaller error)
    first = rectangle(np.zeros(3), np.array([a, 0, 0]), np.array([0, b, 0]))  # faces +z
    second = rectangle(np.array([0, 0, c]), np.array([0, b, 0]), np.array([a, 0, 0]))  # faces -z
    F = _view_factor([(0, *first), (1, *second)], 400_000, 3, qmc)
    assert F == pytest.approx(parallel_rectangles(a, b, c), rel=0.01)


@pytest.mark.parametrize("l,w,h", [(1.0, 1.0, 1.0), (0.4, 0.1, 0.3)])
def test_perpendicular_rectangles_view_factor(l, w, h):
    # surface 1: l (along x) x w (along y) in z = 0, facing +z; surface 2: l x h in y = 0, facing +y.
    # 400k rays: F >= 0.1, binomial std <= 0.16 % relative, 1 % is > 6 sigma
    first = rectangle(np.zeros(3), np.array([l, 0, 0]), np.array([0, w, 0]))
    second = rectangle(np.zeros(3), np.array([0, 0, h]), np.array([l, 0, 0]))
    F = _view_factor([(0, *first), (1, *second)], 400_000, 4)
    assert F == pytest.approx(perpendicular_rectangles(l, w, h), rel=0.01)


def test_specular_mirror_image():
    # A square facing a parallel square mirror (rho_s = 0.9) at height h sees its own mirror
    # image at distance 2 h: F^s_11 = rho_s F(C-11, a, a, 2 h); every ray from the square to its
    # image crosses the mid-plane inside the mirror (convexity), so the finite mirror suffices.
    # 1e6 rays: F ~ 0.18, binomial std 0.2 % relative, so 1 % is ~5 sigma.
    a, h, rho = 1.0, 0.5, 0.9
    square = rectangle(np.zeros(3), np.array([a, 0, 0]), np.array([0, a, 0]))  # faces +z
    mirror = rectangle(np.array([0, 0, h]), np.array([0, a, 0]), np.array([a, 0, 0]))  # faces -z
    enc = build_enclosure([(0, *square), (1, *mirror)], np.array([0.0, rho]))
    F, stats = trace_exchange_factors(
        enc, np.array([1_000_000, 10]), max_bounces=1, min_weight=0.01, rng=np.random.default_rng(6)
    )
    assert F[0, 1] == pytest.approx(parallel_rectangles(a, a, h), rel=0.01)
    assert F[0, 0] == pytest.approx(rho * parallel_rectangles(a, a, 2 * h), rel=0.01)


def test_emission_is_area_uniform_and_lambertian():
    from twin.radiation.raytrace import RAY_OFFSET, _Emitter

    cfg = small_config()
    geo = furnace_geometry(cfg, 0.0)
    enc = geo.enclosure
    lamp = geo.names.index("h1")
    n = 400_000
    origins, dirs = _Emitter(enc).sample(np.full(n, lamp), np.random.default_rng(8))
    # points on the two end caps (y = const) in proportion to their area: binomial, 5 sigma
    own = enc.face_surface == lamp
    caps = own & (np.abs(enc.face_normals[:, 1]) > 0.99)
    expected = enc.face_areas[caps].sum() / enc.area[lamp]
    h = cfg.lamps.horizontal
    y_ends = cfg.specimen.width / 2 + np.array([-1, 1]) * h.heated_length / 2
    on_cap = np.min(np.abs(origins[:, 1, None] - y_ends[None, :]), axis=1) < 2 * RAY_OFFSET
    assert abs(on_cap.mean() - expected) < 5 * math.sqrt(expected / n)
    # cosine-weighted directions about the normal of a front cell (+z): E[cos theta] = 2/3,
    # E[cos^2 theta] = 1/2 (Lambert); std of the means <= 0.25 / sqrt(n) = 4e-4, bounds ~5 sigma
    k = 3 + cfg.specimen.nx * 7
    origins, dirs = _Emitter(enc).sample(np.full(n, k), np.random.default_rng(9))
    cos = dirs[:, 2]
    assert np.all(cos > 0)
    assert np.mean(cos) == pytest.approx(2 / 3, abs=2e-3)
    assert np.mean(cos**2) == pytest.approx(1 / 2, abs=2e-3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-5)
    # points uniform over the cell: mean at the centre, variance dx^2 / 12 (both bounds >= 5 sigma)
    dx = cfg.specimen.length / cfg.specimen.nx
    assert origins[:, 0].mean() == pytest.approx(3.5 * dx, abs=0.01 * dx)
    assert origins[:, 0].var() == pytest.approx(dx**2 / 12, rel=0.01)
    assert np.allclose(origins[:, 2], cfg.specimen.thickness / 2 + RAY_OFFSET, atol=1e-7)


def test_closed_box_has_no_escapes_and_closes():
    # a closed cube with mirrors (rho_s = 0.5): closure sum_j F_ij (1 - rho_s_j) = 1 holds for the
    # raw estimate up to truncation (max 30 bounces, 0.5^30 ~ 1e-9) and roulette noise
    cube = []
    e = np.eye(3)
    for k in range(3):
        u, v = e[(k + 1) % 3], e[(k + 2) % 3]
        cube.append((2 * k, *rectangle(np.zeros(3), u, v)))  # at 0, normal +e_k (inward)
        cube.append((2 * k + 1, *rectangle(e[k], v, u)))  # at 1, normal -e_k (inward)
    rho_s = np.full(6, 0.5)
    enc = build_enclosure(cube, rho_s)
    F, stats = trace_exchange_factors(
        enc, np.full(6, 50_000), max_bounces=30, min_weight=0.01, rng=np.random.default_rng(5)
    )
    assert stats.escaped_weight == 0.0
    # roulette adds noise of order sqrt(min_weight / N) per row: 1e-3 is > 5 sigma
    np.testing.assert_allclose(F @ (1 - rho_s), 1.0, atol=2e-3)
    # opposite faces of a unit cube directly: 0.1998 (C-11); with mirrors more arrives
    assert F[0, 1] > parallel_rectangles(1, 1, 1)


def test_infinite_plates_net_flux_with_specular_reflection():
    # Two infinite parallel plates; plate 1 specular (rho_d = 0), plate 2 diffuse.
    # Arriving fractions: E_12 = 1 / (1 - rs1 rs2), E_11 = rs2 / (1 - rs1 rs2), E_22 = 0, E_21 = 1.
    # Net flux q = sigma (T1^4 - T2^4) / (1/eps1 + 1/eps2 - 1) (Modest, ch. 6), independent of the split.
    # E_22 = rs1 / (1 - rs1 rs2) as well (radiation from 2 comes back off the mirror 1).
    eps1, rs1, eps2 = 0.3, 0.7, 0.6
    T = np.array([1200.0, 500.0])
    expected = STEFAN_BOLTZMANN * (T[0] ** 4 - T[1] ** 4) / (1 / eps1 + 1 / eps2 - 1)
    for rs2 in (0.0, 0.25):
        g = 1 / (1 - rs1 * rs2)
        E = np.array([[rs2 * g, g], [g, rs1 * g]])
        P = net_radiation_matrix(E, np.array([eps1, eps2]), np.array([rs1, rs2]), np.array([0.0, 1 - eps2 - rs2]))
        np.testing.assert_allclose(P @ T**4, [expected, -expected], rtol=1e-12)


def test_fixup_keeps_exact_factors_and_fixes_noisy_ones():
    # exact factors of the half-specular cube are a fixed point up to the balancing tolerance
    A = np.array([1.0, 2.0, 3.0])
    S = np.array([[0.1, 0.5, 0.4], [0.5, 0.6, 0.9], [0.4, 0.9, 1.7]])  # symmetric exchange areas
    rho_s = np.array([0.0, 0.5, 0.0])
    # choose A so that closure holds: A_i = sum_j S_ij (1 - rho_s_j)
    A = S @ (1 - rho_s)
    F = S / A[:, None]
    G, info = enforce_reciprocity_closure(F, A, rho_s)
    np.testing.assert_allclose(G, F, rtol=1e-9)
    noisy = F * np.random.default_rng(0).uniform(0.9, 1.1, F.shape)
    G, info = enforce_reciprocity_closure(noisy, A, rho_s)
    np.testing.assert_allclose(A[:, None] * G, (A[:, None] * G).T, rtol=1e-12)
    np.testing.assert_allclose(G @ (1 - rho_s), 1.0, atol=1e-9)
    assert info.closure_defect_before > 1e-3 and info.closure_defect_after < 1e-9


def test_weighted_fixup_trusts_the_densely_sampled_side():
    # Surface 0 is sampled 1e4x more densely than 1 and 2 (rays per area), so its row is taken
    # nearly as is, while the plain mean inherits half of the +-20 % noise of rows 1 and 2.
    S = np.array([[0.2, 0.5, 0.4], [0.5, 0.6, 0.9], [0.4, 0.9, 1.7]])
    rho_s = np.zeros(3)
    A = S @ (1 - rho_s)
    F = S / A[:, None]
    noisy = F.copy()
    noisy[1:] *= np.random.default_rng(1).uniform(0.8, 1.2, (2, 3))
    rays = np.array([1e6, 100.0, 100.0]) * A
    G_w, _ = enforce_reciprocity_closure(noisy, A, rho_s, rays=rays)
    G_p, _ = enforce_reciprocity_closure(noisy, A, rho_s)
    err_w = np.max(np.abs(G_w[0] - F[0]) / F[0])
    err_p = np.max(np.abs(G_p[0] - F[0]) / F[0])
    assert err_w < 0.5 * err_p
    np.testing.assert_allclose(A[:, None] * G_w, (A[:, None] * G_w).T, rtol=1e-12)
    np.testing.assert_allclose(G_w @ (1 - rho_s), 1.0, atol=1e-9)


# ---- the furnace (small config, cached table) ----


def test_furnace_reciprocity_and_closure(small_radiation):
    cfg = small_config()
    geo = furnace_geometry(cfg, 0.0)
    for k in range(len(small_radiation.eta_nodes)):
        F = small_radiation.exchange[k].astype(float)
        AF = geo.area[:, None] * F
        # enforced after sampling; stored as float32 (relative rounding 6e-8)
        np.testing.assert_allclose(AF, AF.T, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(F @ (1 - geo.specular_reflectivity), 1.0, atol=1e-5)


def test_furnace_raw_estimate_is_closed_without_escapes():
    # the enclosure is closed: no ray may escape; the raw closure defect is only truncation
    cfg = small_config()
    geo = furnace_geometry(cfg, 0.05)
    counts = np.full(geo.n_surfaces, 300)
    F, stats = trace_exchange_factors(
        geo.enclosure, counts, max_bounces=cfg.radiation.max_specular_bounces,
        min_weight=cfg.radiation.min_ray_weight, rng=np.random.default_rng(7),
    )
    assert stats.escaped_weight == 0.0
    # truncated weight after 12 reflections is at most 0.9^12 = 0.28 per ray on the gold reflectors;
    # on average it is tiny (< 1e-3 of the emitted weight)
    assert stats.truncated_fraction < 1e-3
    closure = F @ (1 - geo.specular_reflectivity)
    # 300 rays with roulette: per-row noise ~ sqrt(0.005/300) = 0.004; 0.03 is > 5 sigma
    np.testing.assert_allclose(closure, 1.0, atol=0.03)


def _mirror_permutation(cfg):
    """Surface index map of the mirror y -> W_s - y (cells j -> N_y-1-j, lamps v_j -> v_{N_v+1-j})."""
    s = cfg.specimen
    geo = furnace_geometry(cfg, 0.0)
    ns, nw = s.n_states, geo.n_walls
    k = np.arange(ns)
    i, j = k % s.nx, k // s.nx
    cells = i + s.nx * (s.ny - 1 - j)
    nh, nv = cfg.lamps.horizontal.count, cfg.lamps.vertical.count
    lamps = np.r_[np.arange(nh), nh + (nv - 1 - np.arange(nv))]
    return np.r_[cells, ns + cells, 2 * ns + np.arange(nw), 2 * ns + nw + lamps], geo


def test_mirror_symmetry_statistically(small_radiation):
    """F^s is symmetric about y = W_s/2 within the Monte Carlo error (not enforced)."""
    cfg = small_config()
    perm, geo = _mirror_permutation(cfg)
    F = small_radiation.exchange[len(small_radiation.eta_nodes) // 2].astype(float)
    ns, nw = geo.n_specimen, geo.n_walls
    lamps = slice(2 * ns + nw, None)
    # fraction of each front cell's emission arriving at the lamps: binomial-like with
    # N = rays_per_specimen_cell (the reciprocal estimate from the lamps only lowers the variance)
    n = cfg.radiation.rays_per_specimen_cell
    a = F[:ns, lamps].sum(axis=1)
    b = F[perm[:ns]][:, perm[lamps]].sum(axis=1)
    var = a * (1 - a) / n + b * (1 - b) / n
    # cells fully under a jaw see no lamp from either side
    np.testing.assert_array_equal(a[var == 0], b[var == 0])
    z = (a - b)[var > 0] / np.sqrt(var[var > 0])
    # independent estimates per mirror pair: z ~ N(0, <=1); ~440 values, max |z| < 5 (p ~ 3e-4)
    assert np.max(np.abs(z)) < 5
    # no systematic offset: mean of the (pairwise duplicated) z within 4 sigma of its mean
    assert abs(np.mean(z)) < 4 / math.sqrt(len(z) / 2)
    # the vertical lamps as a whole receive the same share from both halves of the plate
    nh = cfg.lamps.horizontal.count
    v = slice(2 * ns + nw + nh, None)
    a_v, b_v = F[:ns, v], F[perm[:ns]][:, perm[v]]
    np.testing.assert_allclose(a_v.sum(), b_v.sum(), rtol=0.02)  # 442 x 400 rays: std ~ 0.3 %


def test_isothermal_furnace_exchanges_no_heat(small_radiation):
    # closure + reciprocity: everything at one temperature with lamps off gives q_r = 0
    T = 700.0
    q = small_radiation.flux(np.full(small_radiation.n_specimen, T), np.zeros(small_radiation.P2.shape[2]), 0.013,
                             T_w=np.full(len(small_radiation.wall_names), T))
    # float32 storage of F: residual ~1e-6 of sigma T^4
    assert np.max(np.abs(q)) < 1e-5 * STEFAN_BOLTZMANN * T**4


def test_signs_and_lamp_energy_balance(small_radiation):
    cfg = small_config()
    s = cfg.specimen
    rad = small_radiation
    ns = s.n_states
    # a hot specimen in a cold furnace loses heat everywhere
    q = rad.flux(np.full(ns, 1100.0), np.zeros(cfg.lamps.n_lamps), 0.0)
    assert np.all(q > 0)
    # never more than two black faces radiating into vacuum: 2 eps sigma T^4
    assert np.all(q < 2 * s.emissivity * STEFAN_BOLTZMANN * 1100.0**4)
    # lamps heat the specimen; the specimen absorbs at most the lamp's power u pi d l
    cell_area = s.length * s.width / ns
    nominal = furnace_geometry(cfg, 0.0).lamp_nominal_area
    for k in range(len(rad.eta_nodes)):
        assert np.all(rad.P2[k] <= 1e-12)
        absorbed = -cell_area * rad.P2[k].sum(axis=0)
        assert np.all(absorbed <= nominal)
        assert np.all(absorbed > 0.05 * nominal)  # every lamp sees the specimen


def test_interpolation_weights_and_flux(small_radiation):
    rad = small_radiation
    nodes = rad.eta_nodes
    np.testing.assert_array_equal(rad.weights(nodes[1]), np.eye(len(nodes))[1])
    mid = 0.5 * (nodes[1] + nodes[2])
    w = rad.weights(mid)
    np.testing.assert_allclose(w[[1, 2]], [0.5, 0.5])
    assert w.sum() == pytest.approx(1.0)
    T = np.linspace(400, 1100, rad.n_specimen)
    u = 0.3 * rad.lamp_flux_max
    q = rad.flux(T, u, mid)
    x = np.r_[T**4, rad.wall_temperatures**4]
    q1, q2 = (rad.P1[k] @ x + rad.P2[k] @ u for k in (1, 2))
    np.testing.assert_allclose(q, 0.5 * (q1 + q2), rtol=1e-12)
    P1, P2 = rad.matrices(mid)
    np.testing.assert_allclose(P1 @ x + P2 @ u, q, rtol=1e-12)


def test_specimen_emissivity_variant(small_radiation):
    rad = small_radiation
    same = rad.with_specimen_emissivity(small_config().specimen.emissivity)
    np.testing.assert_allclose(same.P1, rad.P1, rtol=1e-10, atol=1e-20)
    darker = rad.with_specimen_emissivity(0.7)
    # a lower emissivity absorbs less lamp power and emits less (grey body, eq. 5)
    assert np.sum(darker.P2) > np.sum(rad.P2)
    T = np.full(rad.n_specimen, 1000.0)
    no_lamps = np.zeros(rad.P2.shape[2])
    assert np.sum(darker.flux(T, no_lamps, 0.0)) < np.sum(rad.flux(T, no_lamps, 0.0))
    assert darker.exchange is rad.exchange
