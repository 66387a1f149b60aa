"""Distributions of the Monte Carlo block of a study file (product.md, "Study file").

Each is a small pydantic model with a ``dist`` tag and a :meth:`sample` that draws ``n`` values from a
numpy ``Generator``:

- ``{dist = "uniform", low, high}``
- ``{dist = "normal", mean, std}``, optionally truncated to ``[low, high]`` (resampled, not clipped, so no
  probability piles up on a bound)
- ``{dist = "integers", low, high}`` (``high`` inclusive)
- ``{dist = "choice", values = [...]}`` (equally likely)

Example
-------
>>> import numpy as np
>>> d = Uniform(low=-0.3, high=0.3)
>>> x = d.sample(np.random.default_rng(1), 1000)
>>> len(x), bool(-0.3 <= min(x) and max(x) <= 0.3)
(1000, True)
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from twin.scenario import Int, Num

#: a truncated normal that rejects more than this fraction of draws is refused (bounds far in the tail)
_MAX_REJECT_ROUNDS = 200


class _Dist(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Uniform(_Dist):
    dist: Literal["uniform"] = "uniform"
    low: Num
    high: Num

    @model_validator(mode="after")
    def _bounds(self) -> Uniform:
        if not self.high > self.low:
            raise ValueError(f"uniform needs high > low (got low = {self.low:g}, high = {self.high:g})")
        return self

    def sample(self, rng: np.random.Generator, n: int) -> list[Any]:
        return [float(v) for v in rng.uniform(self.low, self.high, n)]


class Normal(_Dist):
    dist: Literal["normal"] = "normal"
    mean: Num = 0.0
    std: Num = Field(gt=0.0)
    low: Num | None = Field(None, description="truncate below (resampled)")
    high: Num | None = Field(None, description="truncate above (resampled)")

    @model_validator(mode="after")
    def _bounds(self) -> Normal:
        if self.low is not None and self.high is not None and not self.high > self.low:
            raise ValueError(f"normal: high must be > low (got low = {self.low:g}, high = {self.high:g})")
        return self

    def sample(self, rng: np.random.Generator, n: int) -> list[Any]:
        lo = -np.inf if self.low is None else self.low
        hi = np.inf if self.high is None else self.high
        out = np.empty(0)
        for _ in range(_MAX_REJECT_ROUNDS):
            x = rng.normal(self.mean, self.std, max(n, 16))
            out = np.concatenate([out, x[(x >= lo) & (x <= hi)]])
            if len(out) >= n:
                return [float(v) for v in out[:n]]
        raise ValueError(
            f"normal(mean = {self.mean:g}, std = {self.std:g}) truncated to [{lo:g}, {hi:g}] keeps almost no "
            "draws: the bounds lie far in the tail"
        )


class Integers(_Dist):
    dist: Literal["integers"] = "integers"
    low: Int
    high: Int = Field(description="inclusive")

    @model_validator(mode="after")
    def _bounds(self) -> Integers:
        if self.high < self.low:
            raise ValueError(f"integers needs high >= low (got low = {self.low}, high = {self.high})")
        return self

    def sample(self, rng: np.random.Generator, n: int) -> list[Any]:
        return [int(v) for v in rng.integers(self.low, self.high, n, endpoint=True)]


class Choice(_Dist):
    dist: Literal["choice"] = "choice"
    values: list[Any] = Field(min_length=1)

    def sample(self, rng: np.random.Generator, n: int) -> list[Any]:
        return [self.values[int(i)] for i in rng.integers(0, len(self.values), n)]


Distribution = Annotated[Uniform | Normal | Integers | Choice, Field(discriminator="dist")]
