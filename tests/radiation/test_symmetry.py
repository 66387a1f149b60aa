"""The chamber's mirror symmetries, found (not assumed), and the symmetric trace of the furnace's own table."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated.truth import truth_radiation, truth_radiation_config
from twin.physics.geometry import furnace_geometry
from twin.radiation.cache import cache_path
from twin.radiation.symmetry import (
    conjugate,
    group_average,
    group_of,
    orbit_rays,
    reflection,
    surface_permutation,
    symmetry_plan,
)

CFG = small_config()


def _hand_built(cfg, axis: str) -> np.ndarray:
    """The mirror's surface map written out from the geometry's layout (docs/interfaces.md order):
    y: cell (i, j) -> (i, N_y-1-j), v_k -> v_(N_v+1-k); x: cell (i, j) -> (N_x-1-i, j), housing
    section b -> N_w+1-b, upper <-> lower holder, h_k -> h_(N_h+1-k)."""
    s, geo = cfg.specimen, furnace_geometry(cfg, 0.0)
    ns, nw = s.n_states, geo.n_walls
    k = np.arange(ns)
    i, j = k % s.nx, k // s.nx
    nh, nv = cfg.lamps.horizontal.count, cfg.lamps.vertical.count
    if axis == "y":
        cells = i + s.nx * (s.ny - 1 - j)
        walls = np.arange(nw)
        lamps = np.r_[np.arange(nh), nh + (nv - 1 - np.arange(nv))]
    else:
        cells = (s.nx - 1 - i) + s.nx * j
        nsec = cfg.housing.sections
        walls = np.r_[0, 1, 2 + (nsec - 1 - np.arange(nsec)), nw - 1, nw - 2]
        lamps = np.r_[nh - 1 - np.arange(nh), nh + np.arange(nv)]
    return np.r_[cells, ns + cells, 2 * ns + walls, 2 * ns + nw + lamps]


def test_the_mirrors_that_hold_are_found_and_match_the_layout():
    g0, g1, gm1 = (furnace_geometry(CFG, e) for e in (0.0, 0.025, -0.025))
    np.testing.assert_array_equal(surface_permutation(g0, g0, reflection(CFG, "y")), _hand_built(CFG, "y"))
    np.testing.assert_array_equal(surface_permutation(g1, g1, reflection(CFG, "y")), _hand_built(CFG, "y"))
    # x -> L_s - x maps the chamber at eta onto the one at -eta (and eta = 0 onto itself)
    np.testing.assert_array_equal(surface_permutation(g1, gm1, reflection(CFG, "x")), _hand_built(CFG, "x"))
    np.testing.assert_array_equal(surface_permutation(g0, g0, reflection(CFG, "x")), _hand_built(CFG, "x"))


def test_symmetries_that_do_not_hold_are_refused():
    g0, g1 = furnace_geometry(CFG, 0.0), furnace_geometry(CFG, 0.025)
    assert surface_permutation(g0, g0, reflection(CFG, "z")) is None  # lamps on one side, window on the other
    assert surface_permutation(g1, g1, reflection(CFG, "x")) is None  # a moved specimen is not x-symmetric
    # the same shapes with other optics are not a symmetry: one mirror cell gets another emissivity
    eps = g0.emissivity.copy()
    eps[CFG.specimen.n_states - 1] = 0.5
    assert surface_permutation(g0, replace(g0, emissivity=eps), reflection(CFG, "y")) is None


def test_groups_orbits_and_ray_counts():
    g0 = furnace_geometry(CFG, 0.0)
    px, py = (surface_permutation(g0, g0, reflection(CFG, a)) for a in "xy")
    group = group_of([py, px], g0.n_surfaces)
    assert len(group) == 4  # identity, two mirrors, the half turn about the z axis
    nominal = np.full(g0.n_surfaces, 100, np.int64)
    rays, rep = orbit_rays(group, nominal)
    # every orbit is traced once, and an orbit's rays times its size is the nominal total (x4 cheaper)
    assert np.all(rays[rep] > 0) and np.count_nonzero(rays) == len(np.unique(rep))
    assert rays.sum() == pytest.approx(nominal.sum() / 4, rel=0.02)
    # a reflector is its own mirror image under both: traced once with a quarter of its rays
    refl = 2 * CFG.specimen.n_states
    assert rep[refl] == refl and rays[refl] == 25
    # the plan traces eta >= 0 (eta = 0 with the group of four) and mirrors the rest
    traced, mirrored = symmetry_plan(CFG)
    assert [(k, len(g)) for k, g in traced] == [(2, 4), (3, 2), (4, 2)]
    assert {m: k for m, (k, _) in mirrored.items()} == {0: 4, 1: 3}


def test_group_average_is_exactly_invariant():
    g0 = furnace_geometry(CFG, 0.0)
    group = group_of([surface_permutation(g0, g0, reflection(CFG, a)) for a in "xy"], g0.n_surfaces)
    F = np.random.default_rng(3).random((g0.n_surfaces, g0.n_surfaces))
    G = group_average(F, group)
    for g in group:
        np.testing.assert_array_equal(conjugate(G, g), G)  # bit for bit, not within rounding
    # and it is the mean: for an orbit of four entries the average of the four
    i, j, n = 5, 700, g0.n_surfaces
    orbit = {(int(g[i]), int(g[j])) for g in group}
    assert G[i, j] == pytest.approx(np.mean([F[a, b] for a, b in orbit]), rel=1e-14)
    assert len(orbit) == 4 and n > 700


@pytest.fixture(scope="module")
def truth_table(radiation_cache):
    return truth_radiation(CFG, cache_dir=radiation_cache)


def test_the_truths_table_is_symmetric_reciprocal_and_closed(truth_table):
    etas = truth_table.eta_nodes
    assert np.allclose(etas, -etas[::-1])
    for k, eta in enumerate(etas):
        geo = furnace_geometry(CFG, float(eta))
        F = truth_table.exchange[k]
        py = surface_permutation(geo, geo, reflection(CFG, "y"))
        np.testing.assert_array_equal(conjugate(F, py), F)  # exact, by construction
        m = len(etas) - 1 - k  # F(-eta) is the x-mirror of F(eta), exactly
        px = surface_permutation(geo, furnace_geometry(CFG, float(etas[m])), reflection(CFG, "x"))
        np.testing.assert_array_equal(conjugate(F, px), truth_table.exchange[m])
        F64 = F.astype(float)
        AF = geo.area[:, None] * F64
        # reciprocity and closure enforced after sampling, stored as float32 (relative rounding 6e-8)
        np.testing.assert_allclose(AF, AF.T, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(F64 @ (1 - geo.specular_reflectivity), 1.0, atol=1e-5)
    # P1, P2 come from F through a linear solve: symmetric to rounding
    py = _hand_built(CFG, "y")
    first_lamp = 2 * CFG.specimen.n_states + furnace_geometry(CFG, 0.0).n_walls
    cells, lamps = py[: CFG.specimen.n_states], py[first_lamp:] - first_lamp
    P2 = truth_table.P2[len(etas) // 2]
    np.testing.assert_allclose(P2[cells][:, lamps], P2, rtol=1e-9, atol=1e-12 * np.abs(P2).max())


def test_the_truths_table_is_its_own_trace_unbiased_against_the_models(truth_table, small_radiation):
    """Another seed, more rays, a symmetric trace: the same physics within Monte Carlo noise (the model's
    table is independent), and not the model's numbers."""
    ns = CFG.specimen.n_states
    first_lamp = 2 * ns + furnace_geometry(CFG, 0.0).n_walls
    nh, nv = CFG.lamps.horizontal.count, CFG.lamps.vertical.count
    # front cells -> all lamps; back cells -> the vertical lamps of the y < W_s / 2 half; front cells ->
    # the horizontal lamps of the x < L_s / 2 half: a row filled from its mirror image without the
    # mirror's permutation would hand a cell the far half's share
    shares = ((slice(0, ns), slice(first_lamp, None)),
              (slice(ns, 2 * ns), slice(first_lamp + nh, first_lamp + nh + nv // 2)),
              (slice(0, ns), slice(first_lamp, first_lamp + nh // 2)))
    for cells, lamps in shares:
        for k in (0, len(truth_table.eta_nodes) // 2):
            a = truth_table.exchange[k][cells, lamps].astype(float).sum(axis=1)
            b = small_radiation.exchange[k][cells, lamps].astype(float).sum(axis=1)
            n_a, n_b = CFG.truth.radiation.rays_per_specimen_cell, CFG.radiation.rays_per_specimen_cell
            var = a * (1 - a) / n_a + b * (1 - b) / n_b  # binomial-like per cell; the fix-up only lowers it
            live = var > 0
            z = (a - b)[live] / np.sqrt(var[live])
            assert np.max(np.abs(z)) < 5  # ~440 cells, p ~ 3e-4 per value for a standard normal
            assert abs(np.mean(z)) < 4 / math.sqrt(live.sum() / 4)  # no bias (up to four mirror copies per value)
            assert not np.array_equal(a, b)


def test_truth_and_model_tables_are_cached_apart(radiation_cache):
    model = cache_path(CFG, radiation_cache)
    truth = cache_path(truth_radiation_config(CFG), radiation_cache, symmetric=True)
    assert model != truth and truth.name.startswith("exchange-sym-") and truth.exists()
    # a change of the truth's rays is a new truth table and leaves the model's alone
    other = CFG.with_overrides({"truth.radiation.rays_per_lamp": 17000})
    assert cache_path(other, radiation_cache) == model
    assert cache_path(truth_radiation_config(other), radiation_cache, symmetric=True) != truth
