"""Monte Carlo specular exchange factors F^s of an enclosure (paper eq. 5) with Embree.

``F^s_ij`` is the fraction of the energy emitted (or diffusely reflected) by surface i
that *arrives* at surface j, directly or after any number of specular reflections
(Siegel & Howell's specular exchange factor).  With this definition the energy
balance behind eq. (5) reads H = F^s J, and every emitted ray ends up absorbed or
diffusely reflected somewhere, so the closure is ``sum_j F^s_ij (1 - rho^s_j) = 1``
and the reciprocity ``A_i F^s_ij = A_j F^s_ji`` holds.

Embree (through ``embreex``, the backend of ``trimesh.ray.ray_pyembree``; used directly
with float32 arrays to skip trimesh's per-call conversions) finds the first hit.
Algorithm: rays leave uniformly sampled points of surface i in cosine-weighted
directions about the emitting normal (origin offset :data:`RAY_OFFSET`).  On a hit of
surface j the ray's weight w is added to ``F[i, j]`` and the ray continues in the
mirror direction with weight ``w rho^s_j``.  Below ``min_ray_weight`` a ray plays
Russian roulette (survives with probability w / min_ray_weight at weight
min_ray_weight, which keeps the estimate unbiased); after ``max_specular_bounces``
reflections it stops and its remaining weight is reported as truncated.  Rays that
leave a closed enclosure are counted (a geometry bug) and reported.

Emission uses randomised quasi-Monte Carlo: the k-th ray of every surface takes the
k-th point of one scrambled 6-D Sobol sequence (face, point in the face, direction),
shifted modulo 1 by a random vector per surface (Cranley-Patterson rotation, so the
estimate stays unbiased).  Measured on the default furnace at eta = 0 (two seeds): at
the same ray counts the per-cell noise of P2 u is 1.3x and of the emission 1.5x lower
than with independent random numbers, i.e. about half the rays for the same accuracy.

Example
-------
>>> import numpy as np
>>> from twin.physics.geometry import build_enclosure, rectangle
>>> a = rectangle(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
>>> b = rectangle(np.array([0, 0, 1.0]), np.array([0, 1.0, 0]), np.array([1.0, 0, 0]))
>>> enc = build_enclosure([(0, *a), (1, *b)], np.zeros(2))
>>> F, stats = trace_exchange_factors(enc, np.array([20000, 10]), max_bounces=0,
...                                   min_weight=0.01, rng=np.random.default_rng(1))
>>> bool(abs(F[0, 1] - 0.1998) < 0.01)   # Howell C-11, unit squares at unit distance
True
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from numpy.typing import NDArray

from twin.physics.geometry import Enclosure

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

#: ray origins are moved this far (m) off the surface they leave, against self-hits
RAY_OFFSET = 1.0e-6
#: rays traced per Embree call (memory ~100 bytes per ray)
BATCH_RAYS = 400_000


@dataclass(frozen=True)
class TraceStats:
    """Bookkeeping of one tracing run (weights are in units of emitted rays)."""

    rays: int
    segments: int
    escaped_weight: float
    truncated_weight: float

    @property
    def escaped_fraction(self) -> float:
        return self.escaped_weight / max(self.rays, 1)

    @property
    def truncated_fraction(self) -> float:
        return self.truncated_weight / max(self.rays, 1)


def _alias_tables(weights: Array) -> tuple[Array, NDArray[np.int64]]:
    """Walker/Vose alias table of a discrete distribution: (acceptance probability, alias index)."""
    m = len(weights)
    scaled = np.asarray(weights, float) * m / np.sum(weights)
    prob, alias = np.ones(m), np.arange(m)
    small = [i for i in range(m) if scaled[i] < 1.0]
    large = [i for i in range(m) if scaled[i] >= 1.0]
    while small and large:
        lo, hi = small.pop(), large.pop()
        prob[lo], alias[lo] = scaled[lo], hi
        scaled[hi] -= 1.0 - scaled[lo]
        (small if scaled[hi] < 1.0 else large).append(hi)
    return prob, alias


class _Emitter:
    """Area-uniform points and cosine-weighted directions on the surfaces of an enclosure.

    A face of surface s is drawn in O(1) with an alias table over the faces of s
    (probability = face area / surface area), a point uniformly in the triangle, and a
    direction cos(theta)-distributed about the emitting normal (Malley's method).
    """

    def __init__(self, enc: Enclosure) -> None:
        order = np.argsort(enc.face_surface, kind="stable")
        surf = enc.face_surface[order]
        self.start = np.searchsorted(surf, np.arange(enc.n_surfaces))
        self.n_faces = np.diff(np.r_[self.start, len(order)])
        self.accept = np.ones(len(order), np.float32)
        self.alias = np.arange(len(order))
        for s0, m in zip(self.start, self.n_faces, strict=True):
            prob, alias = _alias_tables(enc.face_areas[order[s0 : s0 + m]])
            self.accept[s0 : s0 + m] = prob
            self.alias[s0 : s0 + m] = s0 + alias
        self.face_of = order
        V, F = enc.vertices, enc.faces
        p0 = V[F[:, 0]]
        e1, e2 = V[F[:, 1]] - p0, V[F[:, 2]] - p0
        n = enc.face_normals
        t1 = e1 / np.linalg.norm(e1, axis=1)[:, None]
        t2 = np.cross(n, t1)
        # per face: origin (offset off the surface), two edges, tangent frame and normal
        self.basis = np.stack([p0 + RAY_OFFSET * n, e1, e2, t1, t2, n], axis=1).astype(np.float32)

    def sample(
        self, src: NDArray[np.int64], rng: np.random.Generator, u: NDArray[np.float32] | None = None
    ) -> tuple[NDArray[np.float32], ...]:
        """Origins and unit directions (float32, (m, 3)) of rays leaving the surfaces ``src``.

        ``u`` (6, m) in [0, 1) are the uniform numbers to use (e.g. randomised quasi-random
        points); drawn from ``rng`` if None.
        """
        m = len(src)
        if u is None:
            u = rng.random((6, m), dtype=np.float32)
        nf = self.n_faces[src]
        slot = self.start[src] + np.minimum((u[0] * nf).astype(np.int64), nf - 1)
        face = np.where(u[5] < self.accept[slot], slot, self.alias[slot])
        B = self.basis[self.face_of[face]]
        r1, r2 = u[1], u[2]
        flip = r1 + r2 > 1
        r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
        rad, phi = np.sqrt(u[3]), np.float32(2 * np.pi) * u[4]
        pts = B[:, 0] + r1[:, None] * B[:, 1] + r2[:, None] * B[:, 2]
        d = (rad * np.cos(phi))[:, None] * B[:, 3] + (rad * np.sin(phi))[:, None] * B[:, 4]
        d += np.sqrt(1 - u[3])[:, None] * B[:, 5]
        return pts, d


def trace_exchange_factors(
    enc: Enclosure,
    rays_per_surface: NDArray[np.int64],
    *,
    max_bounces: int,
    min_weight: float,
    rng: np.random.Generator,
    progress: Callable[[int], None] | None = None,
    qmc: bool = True,
) -> tuple[Array, TraceStats]:
    """Raw Monte Carlo estimate of F^s (eq. 5) for an enclosure.

    Parameters
    ----------
    enc : triangulated surfaces with specular reflectivities
    rays_per_surface : (n,) rays emitted by each surface
    max_bounces : maximum number of specular reflections of a ray
    min_weight : Russian-roulette threshold on the ray weight
    rng : random generator (fixed seed for reproducible tables)
    progress : optional callback with the number of rays just traced
    qmc : randomised quasi-Monte Carlo emission (see the module docstring); plain Monte Carlo if False

    Returns
    -------
    F : (n, n) arriving fractions, row i normalised by the rays emitted by i
    stats : :class:`TraceStats`
    """
    n = enc.n_surfaces
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene=scene, vertices=enc.vertices.astype(np.float32), indices=enc.faces.astype(np.int32))
    emitter = _Emitter(enc)
    rho_s = enc.specular_reflectivity
    face_surface = enc.face_surface
    normals = enc.face_normals.astype(np.float32)
    offset = np.float32(RAY_OFFSET)
    counts = np.asarray(rays_per_surface, np.int64)
    acc = np.zeros(n * n)
    escaped = truncated = 0.0
    segments = 0
    base = None
    if qmc:
        from scipy.stats import qmc as _qmc

        n_max = int(counts.max())
        sobol = _qmc.Sobol(d=6, scramble=True, seed=rng)
        base = sobol.random_base2(max(int(np.ceil(np.log2(max(n_max, 2)))), 1))[:n_max]
    for lo, hi in _chunks(counts, BATCH_RAYS):
        src = np.repeat(np.arange(lo, hi), counts[lo:hi])
        n_chunk = len(src)
        u = None
        if base is not None:
            c = counts[lo:hi]
            local = np.arange(n_chunk) - np.repeat(np.cumsum(c) - c, c)
            shift = rng.random((hi - lo, 6))
            u = np.mod(base[local] + shift[src - lo], 1.0).T.astype(np.float32)
            u = np.minimum(u, np.float32(1 - 2**-24))
        orig, d = emitter.sample(src, rng, u)
        w = np.ones(len(src))
        for bounce in range(max_bounces + 1):
            if len(src) == 0:
                break
            res = scene.run(orig, d, output=1)
            tri = res["primID"].astype(np.int64)
            segments += len(src)
            miss = tri < 0
            if miss.any():
                escaped += float(w[miss].sum())
                keep = ~miss
                src, orig, d, w, tri = src[keep], orig[keep], d[keep], w[keep], tri[keep]
                tfar = res["tfar"][keep]
            else:
                tfar = res["tfar"]
            j = face_surface[tri]
            acc += np.bincount(src * n + j, weights=w, minlength=n * n)
            w = w * rho_s[j]
            alive = w > 0
            if bounce == max_bounces:
                truncated += float(w.sum())
                break
            low = alive & (w < min_weight)
            if low.any():
                survive = rng.random(int(low.sum())) < w[low] / min_weight
                w[low] = np.where(survive, min_weight, 0.0)
                alive[low] = survive
            src, orig, d, w, tri, tfar = src[alive], orig[alive], d[alive], w[alive], tri[alive], tfar[alive]
            nrm = normals[tri]
            dn = np.einsum("ij,ij->i", d, nrm)
            hit = orig + tfar[:, None] * d
            d = d - 2 * dn[:, None] * nrm
            side = np.where(dn < 0, offset, -offset)  # the reflected ray leaves on the side it came from
            orig = hit + side[:, None] * nrm
        if progress is not None:
            progress(n_chunk)
    F = acc.reshape(n, n) / np.maximum(counts, 1)[:, None]
    stats = TraceStats(int(counts.sum()), segments, escaped, truncated)
    return F, stats


def _chunks(counts: NDArray[np.int64], batch: int) -> list[tuple[int, int]]:
    """Ranges [lo, hi) of whole surfaces with about ``batch`` rays each."""
    out, lo, acc = [], 0, 0
    for s, c in enumerate(counts):
        acc += int(c)
        if acc >= batch or s == len(counts) - 1:
            out.append((lo, s + 1))
            lo, acc = s + 1, 0
    return out
