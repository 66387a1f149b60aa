"""The scenario of one run: the body of ``POST /api/runs`` and of ``run --scenario`` (product.md).

Every field has a default, so ``Scenario()`` is the paper's fixed-specimen experiment
with TC4 in the middle.  Validation errors name the field (pydantic), and the backend
turns them into 422 responses.

Example
-------
>>> s = Scenario.model_validate({"oscillation": {"enabled": True}})
>>> s.oscillation.amplitude, s.reference.setpoint
(0.048, 1100.0)
"""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, field_validator

MAX_DURATION_S = 3600.0
MAX_SPEED = 1000.0


class _Model(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class TransitionReference(_Model):
    """The paper's reference: C1 polynomial transition from the initial mean to ``setpoint`` over ``t_E``."""

    setpoint: float = Field(1100.0, gt=300.0, le=1300.0, description="T_ref(t_E) in K")
    t_E: float = Field(120.0, gt=1.0, le=MAX_DURATION_S, description="transition time in s")


class PointsReference(_Model):
    """User-given (time s, temperature K) points, joined C1 (monotone cubic); constant after the last."""

    points: list[tuple[float, float]] = Field(min_length=1)

    @field_validator("points")
    @classmethod
    def _points(cls, v: list[tuple[float, float]]) -> list[tuple[float, float]]:
        ts = [p[0] for p in v]
        if ts[0] < 0:
            raise ValueError("times must be >= 0 s")
        if any(b <= a for a, b in zip(ts, ts[1:], strict=False)):
            raise ValueError("times must be strictly increasing")
        if ts[-1] > MAX_DURATION_S:
            raise ValueError(f"times must be <= {MAX_DURATION_S:g} s")
        for _, temp in v:
            if not 250.0 <= temp <= 1300.0:
                raise ValueError(f"temperature {temp} K is outside the reachable range 250..1300 K")
        return v

    @property
    def setpoint(self) -> float:
        return self.points[-1][1]

    @property
    def t_E(self) -> float:
        """Time at which the last point is reached (s)."""
        return self.points[-1][0]


def _reference_kind(value: Any) -> str:
    if isinstance(value, dict):
        return "points" if "points" in value else "transition"
    return "points" if isinstance(value, PointsReference) else "transition"


#: Either reference form; the discriminator picks the form so errors name the right fields.
Reference = Annotated[
    Annotated[TransitionReference, Tag("transition")] | Annotated[PointsReference, Tag("points")],
    Discriminator(_reference_kind),
]


class OscillationSpec(_Model):
    """eta(t) = amplitude sin(2 pi t / period) (paper section 5.2: 3 L_h sin(2 pi t / Pi), Pi = 0.15 t_E)."""

    enabled: bool = False
    amplitude: float = Field(0.048, ge=0.0, le=0.05, description="m; at most the furnace's eta_max")
    period: float = Field(18.0, ge=1.0, le=600.0, description="s")


class Mismatch(_Model):
    """Relative deviations of the plant from the model (0.05 = plant 5 % higher)."""

    emissivity: float = Field(0.0, ge=-0.5, le=0.1)
    alpha: float = Field(0.0, ge=-0.9, le=2.0)
    lamp_efficiency: float = Field(0.0, ge=-0.5, le=0.5)


class EstimatorChoice(_Model):
    """How the twin estimates (issue 11): the model's motion and whether it calibrates parameters.

    ``motion="averaged", calibrate=False`` is the paper's EKF (section 3.2, eq. 11); the defaults are
    the best measured configuration (README, campaign).
    """

    motion: Literal["averaged", "position_aware"] = Field(
        "position_aware", description="'averaged' (paper, eq. 11) or 'position_aware' (model at eta(t_j))")
    calibrate: bool = Field(True, description="learn lamp efficiency and emissivity online (joint EKF)")


#: The paper's estimator, one setting away from the default.
PAPER_ESTIMATOR = EstimatorChoice(motion="averaged", calibrate=False)


class EstimatorSpec(EstimatorChoice):
    """The run's estimator and, optionally, a shadow estimator on the same TC data (shown beside it)."""

    shadow: EstimatorChoice | None = Field(None, description="a second estimator to compare, or null")


class Scenario(_Model):
    reference: Reference = Field(default_factory=TransitionReference)
    duration: float = Field(240.0, gt=0.0, le=MAX_DURATION_S, description="s")
    oscillation: OscillationSpec = Field(default_factory=OscillationSpec)
    tc4: tuple[float, float] = Field((0.5, 0.5), description="relative (x / L_s, y / W_s)")
    speed: Literal["max"] | float = Field("max", description="'max' or a real-time factor")
    mismatch: Mismatch = Field(default_factory=Mismatch)
    tc_noise: float = Field(1.0, ge=0.0, le=50.0, description="TC noise standard deviation, K")
    seed: int = Field(0, ge=0, le=2**31 - 1)
    estimator: EstimatorSpec = Field(default_factory=EstimatorSpec)

    @field_validator("tc4")
    @classmethod
    def _tc4(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not (0.0 <= v[0] <= 1.0 and 0.0 <= v[1] <= 1.0):
            raise ValueError("tc4 is relative: both coordinates must lie in [0, 1]")
        return v

    @field_validator("speed")
    @classmethod
    def _speed(cls, v: str | float) -> str | float:
        if isinstance(v, str):
            return v
        if not 0.01 <= v <= MAX_SPEED:
            raise ValueError(f"speed must be 'max' or a real-time factor in [0.01, {MAX_SPEED:g}]")
        return float(v)

    def to_json(self) -> str:
        return json.dumps(self.model_dump(mode="json"), sort_keys=True)
