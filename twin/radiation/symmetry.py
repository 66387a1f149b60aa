"""Mirror symmetries of the furnace chamber, and a ray trace of F^s (eq. 5) that has them exactly.

The chamber is built symmetric (:mod:`twin.physics.geometry`): both lamp arrays are centred on
the specimen, the housing and the holder jaws reach equally far beyond both long edges, the
housing's side-wall sections each hold both y faces.  So

* the mirror y -> W_s - y maps the enclosure at every eta onto itself (specimen cell (i, j) to
  (i, N_y - 1 - j), lamp v_k to v_(N_v + 1 - k), the rest to itself);
* the mirror x -> L_s - x maps the enclosure at eta onto the one at -eta (cell (i, j) to
  (N_x - 1 - i, j), h_k to h_(N_h + 1 - k), housing section b to N_w + 1 - b, the upper holder to
  the lower one).  Only the radiation has this symmetry: the gas temperature rises along x and
  the two holders run at different temperatures, so the temperature field does not;
* z -> -z is no symmetry (horizontal lamps on one side, vertical ones behind a window on the
  other); :func:`surface_permutation` finds that out instead of assuming it.

Nothing is assumed: :func:`surface_permutation` checks that every surface's mirror image is a
surface of the target geometry with the same area, vertices and optics, and a symmetry that does
not hold (a user's asymmetric furnace) is simply not used.

:func:`symmetric_exchange_factors` traces only one surface of each orbit of the symmetry group,
with the rays divided by the size of its stabiliser, fills the other rows by permutation and
averages the table over the group; the reciprocity/closure fix-up follows, and a last exact
symmetrisation copies one value to every entry of an orbit of entries.  The table is then
symmetric bit for bit, and per surface it has the accuracy of the nominal ray count at about
1 / |group| of the cost.  :func:`symmetric_exchange_table` also takes F^s(-eta) from F^s(eta).

Example
-------
>>> from twin.config import small_config
>>> from twin.physics.geometry import furnace_geometry
>>> cfg = small_config()
>>> g0 = furnace_geometry(cfg, 0.0)
>>> py = surface_permutation(g0, g0, reflection(cfg, "y"))
>>> int(py[0]), cfg.specimen.nx * (cfg.specimen.ny - 1)    # cell (0, 0) <-> (0, N_y - 1)
(416, 416)
>>> surface_permutation(g0, g0, reflection(cfg, "z")) is None
True
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from twin.config import FurnaceConfig
from twin.physics.geometry import FurnaceGeometry, furnace_geometry
from twin.radiation.exchange import ESCAPE_WARNING, eta_nodes, rays_per_surface, run_positions, trace_message
from twin.radiation.raytrace import trace_exchange_factors
from twin.radiation.reciprocity import enforce_reciprocity_closure

log = logging.getLogger(__name__)
Array = NDArray[np.float64]
Perm = NDArray[np.int64]
Reflection = Callable[[Array], Array]

#: two points closer than this (m) are the same point (the geometry is built in float64 from the config)
POINT_TOLERANCE = 1e-9


def reflection(cfg: FurnaceConfig, axis: str) -> Reflection:
    """The mirror about the specimen's mid-plane normal to ``axis``: x = L_s / 2, y = W_s / 2 or z = 0."""
    k = "xyz".index(axis)
    centre = (cfg.specimen.length / 2, cfg.specimen.width / 2, 0.0)[k]

    def reflect(p: Array) -> Array:
        q = np.array(p, float)
        q[..., k] = 2.0 * centre - q[..., k]
        return q

    return reflect


def _surfaces(geo: FurnaceGeometry) -> tuple[Array, list[Array]]:
    """Area-weighted centroid (n, 3) and vertex array of every surface."""
    enc = geo.enclosure
    tri = enc.vertices[enc.faces]  # (M, 3, 3)
    w = enc.face_areas
    centroid = np.stack([np.bincount(enc.face_surface, weights=w * tri[:, :, k].mean(axis=1),
                                     minlength=enc.n_surfaces) for k in range(3)], axis=1) / enc.area[:, None]
    order = np.argsort(enc.face_surface, kind="stable")
    bounds = np.searchsorted(enc.face_surface[order], np.arange(enc.n_surfaces + 1))
    verts = [np.unique(enc.vertices[enc.faces[order[a:b]]].reshape(-1, 3), axis=0)
             for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    return centroid, verts


def _same_points(a: Array, b: Array, tol: float) -> bool:
    """Every point of a has a point of b within tol and vice versa."""
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return bool(d.min(axis=1).max() <= tol and d.min(axis=0).max() <= tol)


def surface_permutation(src: FurnaceGeometry, dst: FurnaceGeometry, reflect: Reflection,
                        tol: float = POINT_TOLERANCE) -> Perm | None:
    """perm[i] = the surface of ``dst`` that is the mirror image of surface i of ``src``, or None.

    None unless every surface's image has a partner with the same centroid, area, vertices (within
    ``tol`` m), emissivity and reflectivities, and the partners form a bijection.
    """
    if src.n_surfaces != dst.n_surfaces:
        return None
    c_src, v_src = _surfaces(src)
    c_dst, v_dst = _surfaces(dst)
    dist, perm = cKDTree(c_dst).query(reflect(c_src))
    perm = np.asarray(perm, np.int64)
    if np.max(dist) > tol or len(np.unique(perm)) != len(perm):
        return None
    a_src, a_dst = src.area, dst.area
    for name in ("emissivity", "specular_reflectivity", "diffuse_reflectivity"):
        if not np.array_equal(getattr(src, name), getattr(dst, name)[perm]):
            return None
    if not np.allclose(a_src, a_dst[perm], rtol=1e-9, atol=0.0):
        return None
    for i, j in enumerate(perm):
        if len(v_src[i]) != len(v_dst[j]) or not _same_points(reflect(v_src[i]), v_dst[j], tol):
            return None
    return perm


def group_of(generators: list[Perm], n: int) -> list[Perm]:
    """All compositions of the generators (permutations of n surfaces), the identity first."""
    group = [np.arange(n, dtype=np.int64)]
    seen = {group[0].tobytes()}
    frontier = list(group)
    while frontier:
        nxt = []
        for g in frontier:
            for h in generators:
                gh = h[g]
                if gh.tobytes() not in seen:
                    seen.add(gh.tobytes())
                    group.append(gh)
                    nxt.append(gh)
        frontier = nxt
    return group


def _inverse(p: Perm) -> Perm:
    inv = np.empty_like(p)
    inv[p] = np.arange(len(p))
    return inv


def conjugate(F: Array, p: Perm) -> Array:
    """The table of the mirrored enclosure: out[p[i], p[j]] = F[i, j]."""
    q = _inverse(p)
    return F[np.ix_(q, q)]


def group_average(F: Array, group: list[Perm]) -> Array:
    """Mean of F over the group's conjugates, then made exactly invariant: every entry of an orbit of
    entries (i, j) -> (g i, g j) takes the value of the orbit's first entry (no rounding differences)."""
    n = F.shape[0]
    mean = sum(conjugate(F, g) for g in group) / len(group)
    flat = np.arange(n * n, dtype=np.int64)
    i, j = np.divmod(flat, n)
    canonical = np.min(np.stack([g[i] * n + g[j] for g in group]), axis=0)
    return np.asarray(np.asarray(mean).ravel()[canonical].reshape(n, n))


def orbit_rays(group: list[Perm], nominal: NDArray[np.int64]) -> tuple[NDArray[np.int64], Perm]:
    """Rays to trace per surface (one representative per orbit, nominal / stabiliser size, else 0) and
    each surface's representative."""
    n = len(nominal)
    rep = np.full(n, -1, np.int64)
    rays = np.zeros(n, np.int64)
    for i in range(n):
        if rep[i] >= 0:
            continue
        orbit = np.unique([int(g[i]) for g in group])
        rep[orbit] = i
        stabiliser = len(group) // len(orbit)
        rays[i] = math.ceil(int(nominal[orbit].max()) / stabiliser)
    return rays, rep


def symmetric_exchange_factors(
    geo: FurnaceGeometry, group: list[Perm], nominal: NDArray[np.int64], *, max_bounces: int, min_weight: float,
    rng: np.random.Generator,
) -> tuple[Array, str, bool]:
    """Reciprocal, closed, exactly group-invariant F^s (n, n) of one position (see the module docstring).

    Returns F, a log line and whether rays escaped the enclosure.
    """
    rays, rep = orbit_rays(group, nominal)
    F, stats = trace_exchange_factors(geo.enclosure, rays, max_bounces=max_bounces, min_weight=min_weight, rng=rng)
    for k in np.flatnonzero(rep != np.arange(len(rep))):  # rows of the other orbit members
        r = rep[k]
        g = next(g for g in group if g[r] == k)
        F[k, g] = F[r]  # F[k, g[j]] = F[r, j]
    F = group_average(F, group)
    G, fix = enforce_reciprocity_closure(F, geo.area, geo.specular_reflectivity, rays=nominal)
    G = group_average(G, group)
    msg = trace_message(geo.eta, stats, fix) + f" [symmetry group of {len(group)}]"
    return G, msg, stats.escaped_fraction > ESCAPE_WARNING


def _worker(job: tuple[FurnaceConfig, float, np.random.SeedSequence, list[Perm]]) -> tuple[Array, str, bool]:
    cfg, eta, seed, group = job
    geo = furnace_geometry(cfg, eta)
    r = cfg.radiation
    return symmetric_exchange_factors(geo, group, rays_per_surface(cfg, geo), max_bounces=r.max_specular_bounces,
                                      min_weight=r.min_ray_weight, rng=np.random.default_rng(seed))


def symmetry_plan(cfg: FurnaceConfig) -> tuple[list[tuple[int, list[Perm]]], dict[int, tuple[int, Perm]]]:
    """Which positions to trace with which group, and which to take from a mirrored one.

    Returns ``traced`` [(position index, group)] and ``mirrored`` {index: (source index, perm)} with
    F(eta_index) = conjugate(F(eta_source), perm).
    """
    etas = eta_nodes(cfg)
    n = len(etas)
    geos = {k: furnace_geometry(cfg, float(e)) for k, e in enumerate(etas)}
    ry, rx = reflection(cfg, "y"), reflection(cfg, "x")
    traced: list[tuple[int, list[Perm]]] = []
    mirrored: dict[int, tuple[int, Perm]] = {}
    for k in reversed(range(n)):  # eta >= 0 first; eta < 0 from its mirror where the x-mirror holds
        if k in mirrored:
            continue
        m = n - 1 - k
        px = surface_permutation(geos[k], geos[m], rx) if abs(etas[m] + etas[k]) < 1e-12 else None
        py = surface_permutation(geos[k], geos[k], ry)
        gens = [p for p in (py, px if m == k else None) if p is not None]
        traced.append((k, group_of(gens, geos[k].n_surfaces)))
        if px is not None and m != k:
            mirrored[m] = (k, px)
    log.info("symmetric trace: %d of %d positions traced, groups of %s", len(traced), n,
             sorted({len(g) for _, g in traced}))
    return sorted(traced, key=lambda kg: kg[0]), mirrored


def symmetric_exchange_table(
    cfg: FurnaceConfig, *, workers: int | None = None, on_position: Callable[[], None] | None = None
) -> tuple[Array, Array]:
    """F^s at every position of :func:`twin.radiation.exchange.eta_nodes`, traced with the symmetries
    (seeds: children of ``radiation.seed``, one per traced position).  Returns eta (n_eta,) and F."""
    etas = eta_nodes(cfg)
    traced, mirrored = symmetry_plan(cfg)
    seeds = np.random.SeedSequence(cfg.radiation.seed).spawn(len(traced))
    jobs: list[Any] = [(cfg, float(etas[k]), s, g) for (k, g), s in zip(traced, seeds, strict=True)]
    done = run_positions(_worker, jobs, workers=workers, on_position=on_position)
    table: dict[int, Array] = {k: F for (k, _), F in zip(traced, done, strict=True)}
    for m, (k, p) in mirrored.items():
        table[m] = conjugate(table[k], p)
        if on_position:
            on_position()
    return etas, np.stack([table[k] for k in range(len(etas))])
