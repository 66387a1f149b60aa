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

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, field_validator, model_validator

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


class SimulatedPlant(_Model):
    """The run's furnace is simulated in process (``SimulatedFurnace``): any speed."""

    kind: Literal["simulated"] = "simulated"


class OpcUaPlant(_Model):
    """A furnace over OPC UA (a real one, or ``furnace-twin emulate``): real time only.

    Which endpoints a server may connect to, and with which security, is the server's setting
    (``FURNACE_TWIN_OPCUA_*``), never the scenario's.
    """

    kind: Literal["opcua"]
    endpoint: str = Field("opc.tcp://127.0.0.1:4840/furnace-twin/", description="opc.tcp://host:port/path")

    @field_validator("endpoint")
    @classmethod
    def _endpoint(cls, v: str) -> str:
        from twin.furnace.opcua.endpoints import parse_endpoint

        return parse_endpoint(v).url


Plant = Annotated[SimulatedPlant | OpcUaPlant, Field(discriminator="kind")]


class Scenario(_Model):
    reference: Reference = Field(default_factory=TransitionReference)
    duration: float = Field(240.0, gt=0.0, le=MAX_DURATION_S, description="s")
    oscillation: OscillationSpec = Field(default_factory=OscillationSpec)
    tc4: tuple[float, float] = Field((0.5, 0.5), description="relative (x / L_s, y / W_s)")
    speed: Literal["max"] | float = Field("max", description="'max' or a real-time factor")
    mismatch: Mismatch = Field(default_factory=Mismatch)
    tc_noise: float = Field(1.0, ge=0.0, le=50.0, description="TC noise standard deviation, K")
    seed: int = Field(0, ge=0, le=2**31 - 1)
    plant: Plant = Field(default_factory=SimulatedPlant, description="the furnace: simulated, or over OPC UA")

    @model_validator(mode="before")
    @classmethod
    def _real_time_plant(cls, data: Any) -> Any:
        """A furnace over OPC UA runs at real time: its speed defaults to 1."""
        if isinstance(data, dict) and isinstance(data.get("plant"), dict) and data["plant"].get("kind") == "opcua":
            data = {**data}
            data.setdefault("speed", 1.0)
        return data

    @model_validator(mode="after")
    def _speed_of_plant(self) -> Scenario:
        if self.plant.kind == "opcua" and self.speed != 1.0:
            raise ValueError(f"speed: a furnace over OPC UA runs in real time; speed must be 1 (got {self.speed!r})")
        return self

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
