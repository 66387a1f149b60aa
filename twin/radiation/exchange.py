"""Exchange-factor tables F^s(eta_n) of the furnace at the N_eta + 1 positions (paper section 2.1).

``eta_n = -eta_bar + (n - 1) d_eta``, ``d_eta = 2 eta_bar / N_eta`` (paper, before eq. 4).
Each position is ray-traced (:mod:`twin.radiation.raytrace`) with its own child seed of
``radiation.seed`` (so the table does not depend on the number of workers), then made
reciprocal and closed (:mod:`twin.radiation.reciprocity`).  Positions run in up to two
worker processes, because Embree through embreex traces on one core per call; the workers are fresh
interpreters watched for stalls (:mod:`twin.radiation.workers`).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.physics.geometry import FurnaceGeometry, furnace_geometry
from twin.radiation.raytrace import TraceStats, trace_exchange_factors
from twin.radiation.reciprocity import FixUp, enforce_reciprocity_closure
from twin.radiation.workers import STALL_S, run_jobs

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

#: escaped fraction of the ray weight above which the enclosure is reported as leaking
ESCAPE_WARNING = 1e-5
#: worker processes for the positions (the furnace machine has 2 cores)
MAX_WORKERS = 2


def eta_nodes(cfg: FurnaceConfig) -> Array:
    """Table positions eta_n (m), equally spaced on [-eta_bar, eta_bar]; [0] without oscillation."""
    o = cfg.oscillation
    if o.eta_max == 0 or o.positions == 1:
        return np.zeros(1)
    return np.linspace(-o.eta_max, o.eta_max, o.positions)


def rays_per_surface(cfg: FurnaceConfig, geo: FurnaceGeometry) -> NDArray[np.int64]:
    """Rays emitted by each surface: ``radiation.rays_per_{specimen_cell,wall,lamp}``."""
    r = cfg.radiation
    return np.concatenate(
        [
            np.full(2 * geo.n_specimen, r.rays_per_specimen_cell),
            np.full(geo.n_walls, r.rays_per_wall),
            np.full(geo.n_lamps, r.rays_per_lamp),
        ]
    ).astype(np.int64)


def _trace_position(cfg: FurnaceConfig, eta: float, seed: np.random.SeedSequence) -> tuple[Array, str, bool]:
    geo = furnace_geometry(cfg, eta)
    r = cfg.radiation
    rays = rays_per_surface(cfg, geo)
    F, stats = trace_exchange_factors(
        geo.enclosure,
        rays,
        max_bounces=r.max_specular_bounces,
        min_weight=r.min_ray_weight,
        rng=np.random.default_rng(seed),
    )
    G, fix = enforce_reciprocity_closure(F, geo.area, geo.specular_reflectivity, rays=rays)
    return G, trace_message(eta, stats, fix), stats.escaped_fraction > ESCAPE_WARNING


def trace_message(eta: float, stats: TraceStats, fix: FixUp) -> str:
    """One log line on a traced position: rays, losses, and how far the fix-up moved the estimate."""
    # float32 hit points within ~1e-7 m of a chamber corner can put a reflected ray's origin
    # outside the box: ~1e-7 of the weight is expected; more means an open enclosure (ESCAPE_WARNING)
    return (
        f"eta={eta:+.4f} m: {stats.rays} rays, {stats.segments} segments, escaped {stats.escaped_fraction:.2e}, "
        f"truncated {stats.truncated_fraction:.2e}; fix-up: closure defect {fix.closure_defect_before:.2e} -> "
        f"{fix.closure_defect_after:.1e}, exchange moved {fix.moved_fraction:.2%}, "
        f"max relative change of an entry >= 1e-3 of its row {fix.max_relative_change:.2f} ({fix.rounds} rounds)"
    )


def _report(msg: str, escaped: bool) -> None:
    if escaped:
        log.warning("rays escaped the closed enclosure (geometry bug?): %s", msg)
    else:
        log.info("%s", msg)


def exchange_factors_at(cfg: FurnaceConfig, eta: float, seed: np.random.SeedSequence) -> Array:
    """Reciprocal, closed F^s (n, n) of the furnace at one position eta (m), eq. (5)."""
    G, msg, escaped = _trace_position(cfg, eta, seed)
    _report(msg, escaped)
    return G


def _worker(args: tuple[FurnaceConfig, float, np.random.SeedSequence]) -> tuple[Array, str, bool]:
    return _trace_position(*args)


def run_positions(
    worker: Callable[[Any], tuple[Array, str, bool]],
    jobs: list[Any],
    *,
    workers: int | None = None,
    on_position: Callable[[], None] | None = None,
    stall_s: float = STALL_S,
) -> list[Array]:
    """``worker(job)`` for every job (one eta position each), in up to :data:`MAX_WORKERS` processes.

    ``worker`` returns (F, log message, escaped); results come back in the order of ``jobs``.  The
    processes are fresh interpreters (:mod:`twin.radiation.workers`), never forks of this process, which
    may be a multithreaded server; a worker that fails, dies or stalls for ``stall_s`` s raises
    :class:`twin.radiation.workers.TraceFailed` with the reason.
    """
    n_workers = workers if workers is not None else min(MAX_WORKERS, len(jobs), os.cpu_count() or 1)
    if n_workers <= 1:
        out: list[Array] = []
        for job in jobs:
            F, msg, escaped = worker(job)
            _report(msg, escaped)
            out.append(F)
            if on_position:
                on_position()
        return out

    def arrived(_: int, result: tuple[Array, str, bool]) -> None:
        _report(result[1], result[2])
        if on_position:
            on_position()

    def describe(i: int) -> str:
        return f"position {i + 1} of {len(jobs)} (eta = {jobs[i][1]:+.4f} m)"

    done = run_jobs(worker, jobs, workers=n_workers, on_result=arrived, stall_s=stall_s, describe=describe)
    return [F for F, _, _ in done]


def exchange_factor_table(
    cfg: FurnaceConfig, *, workers: int | None = None, on_position: Callable[[], None] | None = None
) -> tuple[Array, Array]:
    """F^s at every table position.

    Returns
    -------
    eta : (n_eta,) m
    F : (n_eta, n, n)
    """
    etas = eta_nodes(cfg)
    seeds = np.random.SeedSequence(cfg.radiation.seed).spawn(len(etas))
    jobs = [(cfg, float(e), s) for e, s in zip(etas, seeds, strict=True)]
    return etas, np.stack(run_positions(_worker, jobs, workers=workers, on_position=on_position))
