"""Disk cache of the exchange-factor table F^s(eta_n) and its matrices P1, P2 (eqs. 4-5).

One ``.npz`` per configuration digest under ``$FURNACE_TWIN_CACHE`` or
``~/.cache/furnace-twin``.  The digest covers every config section F^s or P depends
on (geometry, optics, positions, ray counts and seed) plus :data:`FORMAT_VERSION`
(bumped whenever the tracer changes its results).  Tables of the symmetric trace
(:mod:`twin.radiation.symmetry`, the simulated furnace's own) are separate files,
``exchange-sym-<digest>-v<SYMMETRIC_FORMAT_VERSION>.npz``.  Files are written atomically
(temporary file + ``os.replace``) and computation holds an exclusive lock file, so
two processes asking for the same table compute it once.

``furnace-twin precompute`` calls :func:`precompute_command`.
"""

from __future__ import annotations

import fcntl
import logging
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.radiation.exchange import eta_nodes, exchange_factor_table
from twin.radiation.model import SurfaceOptics, build_matrices, surface_optics
from twin.radiation.symmetry import symmetric_exchange_table

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

CACHE_ENV = "FURNACE_TWIN_CACHE"
#: bump when the geometry or the tracer changes what a given config produces
FORMAT_VERSION = 5
#: the same for the symmetric trace (twin/radiation/symmetry.py)
SYMMETRIC_FORMAT_VERSION = 1
#: config sections that F^s and P1, P2 depend on
DEPENDS_ON = ("specimen", "lamps", "reflector", "housing", "holders", "oscillation", "radiation")


@dataclass(frozen=True, eq=False)
class ExchangeTable:
    """F^s (float32, reciprocal and closed) and P1, P2 at the positions eta (m)."""

    eta: Array
    F: NDArray[np.float32]
    P1: Array
    P2: Array
    optics: SurfaceOptics


def default_cache_dir() -> Path:
    """``$FURNACE_TWIN_CACHE`` if set, else ``~/.cache/furnace-twin``."""
    env = os.environ.get(CACHE_ENV)
    return Path(env) if env else Path.home() / ".cache" / "furnace-twin"


def cache_path(cfg: FurnaceConfig, cache_dir: str | Path | None = None, *, symmetric: bool = False) -> Path:
    """File of the table of ``cfg``: ``exchange-<digest>-v<FORMAT_VERSION>.npz`` (``exchange-sym-...`` for the
    symmetric trace)."""
    d = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    if symmetric:
        return d / f"exchange-sym-{cfg.digest(*DEPENDS_ON)}-v{SYMMETRIC_FORMAT_VERSION}.npz"
    return d / f"exchange-{cfg.digest(*DEPENDS_ON)}-v{FORMAT_VERSION}.npz"


def _load(path: Path, optics: SurfaceOptics) -> ExchangeTable:
    with np.load(path) as z:
        return ExchangeTable(z["eta"], z["F"], z["P1"], z["P2"], optics)


def _save(path: Path, table: ExchangeTable) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, eta=table.eta, F=table.F, P1=table.P1, P2=table.P2)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; the cache is shared by every run of the user
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


#: ``on_position(done, total)``: called as positions of the table are ray-traced (a server's warm-up)
ProgressFn = Callable[[int, int], None]


def compute_table(cfg: FurnaceConfig, *, progress: bool = False, workers: int | None = None,
                  symmetric: bool = False, on_position: ProgressFn | None = None) -> ExchangeTable:
    """Ray-trace F^s at every position (plainly, or with the furnace's mirror symmetries) and build P1, P2
    (no cache involved)."""
    optics = surface_optics(cfg)
    n = len(eta_nodes(cfg))
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n, desc="exchange factors", unit="position")
    done = 0
    if on_position is not None:
        on_position(0, n)  # the total is known from the first second

    def one_more() -> None:
        nonlocal done
        done += 1
        if bar is not None:
            bar.update()
        if on_position is not None:
            on_position(done, n)

    try:
        trace = symmetric_exchange_table if symmetric else exchange_factor_table
        eta, F = trace(cfg, workers=workers, on_position=one_more)
    finally:
        if bar is not None:
            bar.close()
    F32 = F.astype(np.float32)  # stored precision; P is built from it so reloads are consistent
    P1, P2 = build_matrices(F32, optics)
    return ExchangeTable(eta, F32, P1, P2, optics)


def load_or_compute(
    cfg: FurnaceConfig, *, cache_dir: str | Path | None = None, progress: bool = False, force: bool = False,
    symmetric: bool = False, on_position: ProgressFn | None = None,
) -> ExchangeTable:
    """The table of ``cfg`` from the cache, computing and storing it if missing (or ``force``);
    ``on_position(done, total)`` follows a ray trace."""
    path = cache_path(cfg, cache_dir, symmetric=symmetric)
    optics = surface_optics(cfg)
    if path.exists() and not force:
        try:
            return _load(path, optics)
        except (OSError, ValueError, KeyError) as exc:
            log.warning("unreadable radiation cache %s (%s); recomputing", path, exc)
            force = True
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # a concurrent process computing the same table finishes first
        if path.exists() and not force:
            return _load(path, optics)
        t0 = time.perf_counter()
        log.info("ray-tracing exchange factors for %d positions into %s", len(eta_nodes(cfg)), path)
        table = compute_table(cfg, progress=progress, symmetric=symmetric, on_position=on_position)
        _save(path, table)
        log.info("exchange factors computed in %.1f s", time.perf_counter() - t0)
        return table


def emissivity_path(table_file: Path, eps: float) -> Path:
    """Where P1, P2 of the table in ``table_file`` for the specimen emissivity ``eps`` are kept: beside it, named
    by the exact float (``float.hex``), so a hit returns the matrices a build would make, to the bit."""
    return table_file.with_name(f"{table_file.stem}-emissivity-{float(eps).hex()}.npz")


def emissivity_matrices(table_file: Path, eps: float, build: Callable[[], tuple[Array, Array]]) -> tuple[Array, Array]:
    """P1, P2 (eq. 5) of a cached table with the specimen emissivity ``eps``: from the cache beside ``table_file``,
    else ``build()`` and stored there (atomically, float64 as built; a file that cannot be read is rebuilt).
    They are only as valid as the table beside them: both are named by its digest and :data:`FORMAT_VERSION`."""
    path = emissivity_path(Path(table_file), eps)
    if path.exists():
        try:
            with np.load(path) as z:
                return np.asarray(z["P1"]), np.asarray(z["P2"])
        except (OSError, ValueError, KeyError) as exc:
            log.warning("unreadable emissivity matrices %s (%s); rebuilding", path, exc)
    P1, P2 = build()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez(f, P1=P1, P2=P2)
            os.chmod(tmp, 0o644)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError as exc:  # a read-only cache: the matrices are still right, only not kept
        log.warning("could not keep the emissivity matrices in %s: %s", path, exc)
    return P1, P2


def precompute_seconds(cfg: FurnaceConfig, *, symmetric: bool = False) -> float:
    """Wall time (s) of a cold computation of the whole table into a temporary cache dir (for the bench)."""
    with tempfile.TemporaryDirectory(prefix="furnace-twin-bench-") as d:
        t0 = time.perf_counter()
        load_or_compute(cfg, cache_dir=d, symmetric=symmetric)
        return time.perf_counter() - t0


def precompute_table(cfg: FurnaceConfig, force: bool, *, symmetric: bool = False) -> None:
    """Fill the cache with one table of ``cfg`` (progress bar), log where and how long."""
    path = cache_path(cfg, symmetric=symmetric)
    if path.exists() and not force:
        t0 = time.perf_counter()
        load_or_compute(cfg, symmetric=symmetric)
        log.info("radiation cache is up to date: %s (loaded in %.2f s)", path, time.perf_counter() - t0)
        return
    t0 = time.perf_counter()
    load_or_compute(cfg, progress=True, force=force, symmetric=symmetric)
    log.info("radiation cache written: %s (%.1f s, %.1f MB)", path, time.perf_counter() - t0,
             path.stat().st_size / 1e6)


def precompute_command(cfg: FurnaceConfig, force: bool) -> int:
    """``furnace-twin precompute`` for the model's table of ``cfg`` (the CLI adds the simulated furnace's)."""
    precompute_table(cfg, force)
    return 0
