"""Case expansion: a study (spec) on a furnace -> the list of closed-loop runs it asks for.

The grid is the full factorial of its value lists, in file order (the last path varies fastest).  The
Monte Carlo block draws ``n`` samples of every listed field from the study's own seed: field ``f`` uses
``numpy.random.default_rng([seed, crc32(f)])``, so a field's samples do not change when another field is
added, and sample ``i`` is the same at every grid point (common random numbers: grid points are compared
on the same model errors).  With both blocks, each grid point is run with each sample.

Each case is keyed by the furnace and its scenario (:func:`case_key`): a re-run of a study finds the cases
an earlier invocation finished under the same key, whatever their order in the file.

Example
-------
>>> from twin.config import small_config
>>> spec = parse_study({"grid": {"tc_noise": [0.5, 1.0]}, "monte_carlo": {"n": 3, "mismatch.alpha":
...     {"dist": "uniform", "low": -0.1, "high": 0.1}}})
>>> len(expand(spec, small_config()))
6
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import SHIPPED_FURNACES, ConfigError, FurnaceConfig, load_config
from twin.limits import ScenarioLimits, scenario_limits
from twin.scenario import Scenario
from twin.studies.spec import MonteCarlo, StudyError, StudySpec, check_paths, parse_study, scenario_of, set_path

__all__ = ["Case", "case_key", "expand", "grid_points", "mc_samples", "parse_study", "resolve_furnace"]


@dataclass(frozen=True)
class Case:
    """One closed-loop run of a study."""

    index: int
    key: str
    params: dict[str, Any]  # the varied fields (path -> value)
    scenario: Scenario
    grid_point: int | None  # index into the grid's points (None without a grid)
    sample: int | None  # Monte Carlo sample (None without one)


def case_key(furnace_digest: str, scenario: Scenario) -> str:
    """16 hex digits of sha256(furnace digest, scenario JSON): the identity of a case across invocations."""
    return hashlib.sha256(f"{furnace_digest}\n{scenario.to_json()}".encode()).hexdigest()[:16]


def grid_points(grid: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """Full factorial of the grid, in file order; one empty point without a grid."""
    paths = list(grid)
    return [dict(zip(paths, combo, strict=True)) for combo in itertools.product(*(grid[p] for p in paths))]


def mc_samples(mc: MonteCarlo | None) -> list[dict[str, Any]]:
    """The ``n`` Monte Carlo samples (path -> value); one empty sample without a block."""
    if mc is None:
        return [{}]
    columns: dict[str, list[Any]] = {}
    for path, dist in mc.fields.items():
        try:
            columns[path] = dist.sample(np.random.default_rng([mc.seed, zlib.crc32(path.encode())]), mc.n)
        except ValueError as exc:  # e.g. a truncated normal whose bounds lie far in the tail
            raise StudyError(f"monte_carlo {path!r}: {exc}") from None
    if mc.seeds == "per_sample":
        rng = np.random.default_rng([mc.seed, zlib.crc32(b"seed")])
        columns["seed"] = [int(s) for s in rng.integers(0, 2**31 - 1, mc.n)]
    return [{p: col[i] for p, col in columns.items()} for i in range(mc.n)]


def expand(spec: StudySpec, cfg: FurnaceConfig, limits: ScenarioLimits | None = None) -> list[Case]:
    """Every case of the study on ``cfg``, validated against the scenario schema and the furnace's ``limits``
    (default ``scenario_limits(cfg)``); fields the study leaves out take the furnace's defaults.

    Raises :class:`StudyError` naming each bad path or value, or the first invalid case and why.
    """
    limits = limits or scenario_limits(cfg)
    check_paths(spec, limits)
    digest = cfg.digest()
    points = grid_points(spec.grid)
    samples = mc_samples(spec.monte_carlo)
    has_grid, has_mc = bool(spec.grid), spec.monte_carlo is not None
    cases = []
    for index, ((g, point), (s, sample)) in enumerate(itertools.product(enumerate(points), enumerate(samples))):
        params = {**point, **sample}
        data = copy.deepcopy(spec.base)
        for path, value in params.items():
            set_path(data, path, value)
        where = f"case {index} ({', '.join(f'{p} = {v!r}' for p, v in params.items())})"
        scenario = scenario_of(data, where, limits)
        cases.append(Case(index, case_key(digest, scenario), params, scenario,
                          g if has_grid else None, s if has_mc else None))
    return cases


def resolve_furnace(
    spec: StudySpec, default: FurnaceConfig, *, default_name: str = "default", relative_to: Path | None = None,
    allow_paths: bool = True,
) -> tuple[str, FurnaceConfig]:
    """The study's furnace (name, config): ``default`` (called ``default_name``) when the study names none,
    else a shipped furnace, or (``allow_paths``) a TOML path, relative to the study file's folder."""
    if spec.furnace is None:
        return default_name, default
    name = spec.furnace
    if name not in SHIPPED_FURNACES:
        if not allow_paths:
            raise StudyError(f"furnace: {name!r} is not a shipped furnace ({', '.join(SHIPPED_FURNACES)})")
        p = Path(name)
        if relative_to is not None and not p.is_absolute():
            p = relative_to / p
        name = str(p)
    try:
        return spec.furnace, load_config(name)
    except ConfigError as exc:
        raise StudyError(f"furnace: {exc}") from None
