"""The study file (product.md, "Study file"): a furnace, a base scenario, a grid and/or a Monte Carlo block.

The same document is the TOML file of ``furnace-twin study FILE.toml`` and the JSON body of
``POST /api/studies``::

    furnace = "banded"                  # a shipped furnace or a path; default: the --config furnace
    name = "period x amplitude"         # optional title
    [base]                              # a scenario (twin.scenario.Scenario); every field optional
    oscillation = {enabled = true}
    [grid]                              # scenario field path -> values; full factorial, in file order
    "oscillation.period" = [6.0, 12.0, 18.0]
    [monte_carlo]                       # optional; crossed with the grid when both are given
    n = 50                              # samples
    seed = 1                            # the study's own seed: the same file draws the same samples
    seeds = "per_sample"                # each sample its own TC-noise seed (default), or "base"
    "mismatch.alpha" = {dist = "uniform", low = -0.3, high = 0.3}

:func:`parse_study` checks the document's structure; :func:`check_paths` (called by
:func:`twin.studies.cases.expand`, which knows the furnace) checks every field path and grid value against
the scenario schema and the furnace's limits (``twin.limits``).  Errors are :class:`StudyError` with one
line per problem that names the key.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from twin.limits import ScenarioLimits
from twin.scenario import Int, Scenario, parse_scenario
from twin.studies.distributions import Distribution

#: the most cases one study may expand to (a typo like n = 5000000 is refused, not attempted)
MAX_CASES = 100_000
MC_KEYWORDS = ("n", "seed", "seeds", "fields")


class StudyError(ValueError):
    """A study file or body is invalid; the message names each bad key."""


class MonteCarlo(BaseModel):
    """``n`` samples of the listed scenario fields, drawn from the study's own ``seed``.

    Any key other than ``n``, ``seed`` and ``seeds`` is a scenario field path with its distribution.
    ``seeds = "per_sample"`` gives each sample its own TC-noise seed (drawn from the study seed too);
    ``"base"`` keeps the base scenario's seed for all samples.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    n: Int = Field(ge=1, le=MAX_CASES, description="number of samples")
    seed: Int = Field(0, ge=0, le=2**32 - 1, description="the study's sampling seed")
    seeds: Literal["per_sample", "base"] = "per_sample"
    fields: dict[str, Distribution] = Field(default_factory=dict)

    @model_validator(mode="before")
    @classmethod
    def _collect_fields(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        given = data.get("fields")
        if "fields" in data and not isinstance(given, dict):  # null too: the schema says an object
            raise ValueError("fields: a table of scenario field path -> distribution, "
                             f"got {'null' if given is None else type(given).__name__}")
        fields = dict(given or {})
        fields.update({k: v for k, v in data.items() if k not in MC_KEYWORDS})
        return {**{k: v for k, v in data.items() if k in MC_KEYWORDS}, "fields": fields}

    def document(self) -> dict[str, Any]:
        """The block as written in a study file (field paths beside n, seed, seeds)."""
        return {"n": self.n, "seed": self.seed, "seeds": self.seeds,
                **{p: d.model_dump() for p, d in self.fields.items()}}


#: OpenAPI: what ``StudySpec._consistent`` and ``_grid`` check of the structure: a non-empty grid and/or a
#: Monte Carlo block, and every grid path with at least one value
_STUDY_SCHEMA: dict[str, Any] = {
    "anyOf": [{"required": ["grid"], "properties": {"grid": {"minProperties": 1}}},
              {"required": ["monte_carlo"], "properties": {"monte_carlo": {"type": "object"}}}],
}


class StudySpec(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", json_schema_extra=_STUDY_SCHEMA)

    name: str | None = Field(None, max_length=200, description="a title for tables and the dashboard")
    furnace: str | None = Field(None, min_length=1, max_length=500,
                                description="shipped furnace name or TOML path; default: the running furnace")
    base: dict[str, Any] = Field(default_factory=dict, description="the base scenario; every field optional")
    grid: dict[str, list[Any]] = Field(default_factory=dict, description="field path -> values (full factorial)",
                                       json_schema_extra={"additionalProperties": {"type": "array", "minItems": 1}})
    monte_carlo: MonteCarlo | None = None

    @field_validator("grid")
    @classmethod
    def _grid(cls, grid: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for path, values in grid.items():
            if not values:
                raise ValueError(f"{path!r} has no values")
        return grid

    @model_validator(mode="after")
    def _consistent(self) -> StudySpec:
        if not self.grid and self.monte_carlo is None:
            raise ValueError("a study needs a [grid] and/or a [monte_carlo] block (one run is `furnace-twin run`)")
        mc_paths = set(self.monte_carlo.fields) if self.monte_carlo else set()
        both = sorted(set(self.grid) & mc_paths)
        if both:
            raise ValueError(f"{', '.join(both)}: given in both [grid] and [monte_carlo]")
        varied = sorted(set(self.grid) | mc_paths)
        nested = [(a, b) for a in varied for b in varied if b.startswith(a + ".")]
        if nested:
            a, b = nested[0]
            raise ValueError(f"{a!r} and {b!r}: a field and a field inside it cannot both be varied")
        if self.monte_carlo is not None and self.monte_carlo.seeds == "per_sample" and (
            "seed" in self.grid or "seed" in mc_paths
        ):
            raise ValueError('"seed" is varied explicitly: set seeds = "base" in [monte_carlo]')
        if self.n_cases > MAX_CASES:
            raise ValueError(f"{self.n_cases} cases: at most {MAX_CASES} per study")
        return self

    @property
    def n_cases(self) -> int:
        grid = math.prod(len(v) for v in self.grid.values()) if self.grid else 1
        return grid * (self.monte_carlo.n if self.monte_carlo else 1)

    def varied(self) -> list[str]:
        """The field paths that differ between cases (grid, then Monte Carlo, then "seed" if per sample)."""
        paths = list(self.grid)
        if self.monte_carlo is not None:
            paths += list(self.monte_carlo.fields)
            if self.monte_carlo.seeds == "per_sample":
                paths.append("seed")
        return paths

    def document(self) -> dict[str, Any]:
        """The study as a study-file document (TOML / JSON body layout)."""
        doc: dict[str, Any] = {"base": self.base, "grid": self.grid}
        if self.name is not None:
            doc["name"] = self.name
        if self.furnace is not None:
            doc["furnace"] = self.furnace
        if self.monte_carlo is not None:
            doc["monte_carlo"] = self.monte_carlo.document()
        return doc


def set_path(data: dict[str, Any], path: str, value: Any) -> None:
    """Set ``data["a"]["b"] = value`` for the path ``"a.b"``, creating groups that are missing."""
    *parents, leaf = path.split(".")
    node = data
    for i, key in enumerate(parents):
        child = node.setdefault(key, {})
        if not isinstance(child, dict):
            raise StudyError(f"{path}: {'.'.join(parents[: i + 1])} is a value, not a group of fields")
        node = child
    node[leaf] = value


def format_errors(exc: ValidationError, prefix: str = "") -> list[str]:
    """One line per pydantic error; keys holding dots (field paths) are quoted."""
    lines = []
    for err in exc.errors():
        parts = [repr(p) if isinstance(p, str) and "." in p else str(p) for p in err["loc"]]
        loc = ".".join(([prefix] if prefix else []) + parts) or "(top level)"
        lines.append(f"{loc}: {err['msg'].removeprefix('Value error, ')}")
    return lines


def scenario_of(data: dict[str, Any], where: str, limits: ScenarioLimits | None = None) -> Scenario:
    """Validate a scenario document against a furnace's ``limits`` (default: the default furnace's); fields
    left out take that furnace's defaults.  A :class:`StudyError` names ``where`` and the fields."""
    try:
        return parse_scenario(data, limits)
    except ValidationError as exc:
        raise StudyError(f"{where}: " + "; ".join(format_errors(exc))) from None


def parse_study(doc: Any) -> StudySpec:
    """Validate a study document's structure (parsed TOML or a JSON body); the paths are checked by
    :func:`check_paths` once the furnace is known."""
    if not isinstance(doc, dict):
        raise StudyError("a study must be a table / JSON object")
    try:
        spec = StudySpec.model_validate(doc)
    except ValidationError as exc:
        raise StudyError("invalid study:\n  " + "\n  ".join(format_errors(exc))) from None
    return spec


def check_paths(spec: StudySpec, limits: ScenarioLimits | None = None) -> None:
    """Every path names a scenario field and every grid value is valid there for a furnace's ``limits``
    (each value checked on its own, so each problem is named once)."""
    problems: list[str] = []
    for where, data in _probes(spec):
        try:
            scenario_of(data, where, limits)
        except StudyError as exc:
            problems.append(str(exc))
    if problems:
        raise StudyError("invalid study:\n  " + "\n  ".join(problems))


def _probes(spec: StudySpec) -> list[tuple[str, dict[str, Any]]]:
    """The base alone, and the base with each grid value and each Monte Carlo field set on its own."""
    import copy

    probes: list[tuple[str, dict[str, Any]]] = [("base", spec.base)]
    for path, values in spec.grid.items():
        for v in values:
            data = copy.deepcopy(spec.base)
            set_path(data, path, v)
            probes.append((f"grid {path!r} = {v!r}", data))
    if spec.monte_carlo is not None:
        for path, dist in spec.monte_carlo.fields.items():
            data = copy.deepcopy(spec.base)
            set_path(data, path, _typical(dist))
            probes.append((f"monte_carlo {path!r}", data))
    return probes


def _typical(dist: Any) -> Any:
    """A value the distribution can produce (its centre), to check the path and the field's type."""
    if dist.dist == "uniform":
        return 0.5 * (dist.low + dist.high)
    if dist.dist == "normal":
        lo = -math.inf if dist.low is None else dist.low
        hi = math.inf if dist.high is None else dist.high
        return min(max(dist.mean, lo), hi)
    if dist.dist == "integers":
        return dist.low
    return dist.values[0]


def load_study(path: str | Path) -> StudySpec:
    """Read and validate a study TOML file."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise StudyError(f"cannot read study {p}: {exc.strerror}") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"study {p} is not valid TOML: {exc}") from None
    try:
        return parse_study(doc)
    except StudyError as exc:
        raise StudyError(f"study {p}: {exc}") from None  # paths: checked with the furnace (cases.expand)
