"""The scenario of one run: the body of ``POST /api/runs`` and of ``run --scenario`` (product.md).

Every field has a default, so ``Scenario()`` is the paper's fixed-specimen experiment
with TC4 in the middle.  Validation errors name the field (pydantic), and the backend
turns them into 422 responses.

Bounds and defaults come from ``twin.limits``.  Those that depend on the furnace (the
oscillation amplitude at most its ``eta_max``, the setpoint and reference-point range,
the default amplitude, TC4 position and TC noise) are checked against the limits given
as validation context -- :func:`parse_scenario` and friends, or
``Scenario.model_validate(data, context={"limits": limits})`` -- and a field left out
takes that furnace's default.  Without a context, the default furnace's limits apply.

Example
-------
>>> s = Scenario.model_validate({"oscillation": {"enabled": True}})
>>> s.oscillation.amplitude, s.reference.setpoint
(0.048, 1100.0)
>>> from twin.config import small_config
>>> from twin.limits import scenario_limits
>>> low = scenario_limits(small_config().with_overrides({"oscillation.eta_max": 0.03}))
>>> parse_scenario({"oscillation": {"enabled": True}}, low).oscillation.amplitude
0.03
"""

from __future__ import annotations

import hashlib
import json
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Strict,
    Tag,
    TypeAdapter,
    ValidationInfo,
    field_validator,
    model_validator,
)

from twin import limits as lim
from twin.limits import ScenarioLimits, default_limits

MAX_DURATION_S = lim.MAX_DURATION_S
MAX_SPEED = lim.SPEED.hi
_DEFAULT = default_limits()  # the Field defaults below: the default furnace's (its file is the owner)


def _context_limits(info: ValidationInfo) -> ScenarioLimits | None:
    """The furnace limits given as validation context, if any."""
    given = info.context.get("limits") if isinstance(info.context, dict) else None
    return given if isinstance(given, ScenarioLimits) else None


def _limits(info: ValidationInfo) -> ScenarioLimits:
    """The furnace limits of this validation: the context's, else the default furnace's."""
    return _context_limits(info) or _DEFAULT


def _furnace_default(data: Any, info: ValidationInfo, name: str) -> Any:
    """With a furnace's limits in the context, a field ``name`` left out takes that furnace's default
    (``ScenarioLimits.<name>.default``); without them the model's own default stands."""
    given = _context_limits(info)
    if given is not None and isinstance(data, dict):
        return {name: getattr(given, name).default, **data}
    return data


def _check(r: lim.Range, value: float) -> float:
    problem = r.problem(value)
    if problem is not None:
        raise ValueError(problem)
    return value


#: A JSON number: an int or a float, never a bool or a string ("speed": true is not 1.0), never NaN or
#: +-Infinity (the models below refuse non-finite floats: a JSON body with NaN, Infinity or 1e999 is a 422)
Num = Annotated[float, Strict()]
def _whole(value: Any) -> Any:
    """A whole float (2.0) as the int JSON Schema counts it as ("integer" takes 2.0); anything else as given."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


#: A JSON integer: 2 or 2.0 (JSON Schema's "integer"), never 2.5, a bool or a string
Int = Annotated[int, Strict(), BeforeValidator(_whole)]
#: A JSON true or false, never 0 / 1 or "yes" (the schema says boolean; a lax 0 was taken as false)
Flag = Annotated[bool, Strict()]


class _Model(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class TransitionReference(_Model):
    """The paper's reference: C1 polynomial transition from the initial mean to ``setpoint`` over ``t_E``."""

    setpoint: Num = Field(_DEFAULT.setpoint.default, description="T_ref(t_E) in K; range: GET /api/furnace")
    t_E: Num = Field(lim.T_E.default, gt=lim.T_E.lo, le=lim.T_E.hi, description="transition time in s")

    @model_validator(mode="before")
    @classmethod
    def _furnace_defaults(cls, data: Any, info: ValidationInfo) -> Any:
        return _furnace_default(data, info, "setpoint")

    @field_validator("setpoint")
    @classmethod
    def _setpoint(cls, v: float, info: ValidationInfo) -> float:
        return _check(_limits(info).setpoint, v)


class PointsReference(_Model):
    """User-given (time s, temperature K) points, joined C1 (monotone cubic); constant after the last."""

    points: list[tuple[Num, Num]] = Field(min_length=1, max_length=lim.MAX_REFERENCE_POINTS,
                                          description=f"(t s, T K), at most {lim.MAX_REFERENCE_POINTS}")

    @field_validator("points")
    @classmethod
    def _points(cls, v: list[tuple[float, float]], info: ValidationInfo) -> list[tuple[float, float]]:
        ts = [p[0] for p in v]
        if ts[0] < 0:
            raise ValueError("times must be >= 0 s")
        if any(b <= a for a, b in zip(ts, ts[1:], strict=False)):
            raise ValueError("times must be strictly increasing")
        if ts[-1] > lim.POINT_TIME.hi:
            raise ValueError(f"times must be <= {lim.POINT_TIME.hi:g} s")
        temps = _limits(info).point_temperature
        for _, temp in v:
            if temps.problem(temp) is not None:
                raise ValueError(f"temperature {temp} K is outside the reachable range {temps.lo:g}..{temps.hi:g} K")
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

    enabled: Flag = False
    amplitude: Num = Field(_DEFAULT.amplitude.default, ge=0.0,
                             description="m; at most the furnace's eta_max, default 3 L_h capped at it "
                                         "(GET /api/furnace)")
    period: Num = Field(lim.PERIOD.default, ge=lim.PERIOD.lo, le=lim.PERIOD.hi, description="s")

    @model_validator(mode="before")
    @classmethod
    def _furnace_defaults(cls, data: Any, info: ValidationInfo) -> Any:
        return _furnace_default(data, info, "amplitude")

    @field_validator("amplitude")
    @classmethod
    def _amplitude(cls, v: float, info: ValidationInfo) -> float:
        return _check(_limits(info).amplitude, v)


class Mismatch(_Model):
    """Relative deviations of the plant from the model (0.05 = plant 5 % higher)."""

    emissivity: Num = Field(0.0, ge=lim.MISMATCH_EMISSIVITY.lo, le=lim.MISMATCH_EMISSIVITY.hi)
    alpha: Num = Field(0.0, ge=lim.MISMATCH_ALPHA.lo, le=lim.MISMATCH_ALPHA.hi)
    lamp_efficiency: Num = Field(0.0, ge=lim.MISMATCH_LAMP_EFFICIENCY.lo, le=lim.MISMATCH_LAMP_EFFICIENCY.hi)


FaultKind = Literal["stuck", "drift", "offset", "dropout", "failed", "derate"]


class FaultSpec(_Model):
    """A fault injected into the simulated furnace at run time ``at`` (product.md, ``faults``).

    TC1..TC4: ``stuck`` (reads the value it had at ``at``), ``drift`` (``value`` K/s added from ``at``),
    ``offset`` (``value`` K added), ``dropout`` (no reading: status "bad").  A lamp group (a name of
    ``GET /api/furnace``'s groups): ``failed`` (no power), ``derate`` (keeps the fraction ``value``).
    In ``PUT /api/runs/{id}/faults``, ``at`` counts from now.
    """

    at: Num = Field(lim.FAULT_AT.default, ge=lim.FAULT_AT.lo, le=lim.FAULT_AT.hi,
                      description="s of run time (of a PUT: from now)")
    target: str = Field(description="TC1..TC4, or a lamp group name (GET /api/furnace)")
    kind: FaultKind
    value: Num | None = Field(None, description="drift K/s, offset K, derate fraction kept; "
                                                  "none for stuck, dropout, failed")

    @model_validator(mode="after")
    def _consistent(self, info: ValidationInfo) -> FaultSpec:
        groups = _limits(info).groups
        on_tc = self.kind in lim.TC_FAULT_KINDS
        if on_tc and self.target not in lim.TC_NAMES:
            raise ValueError(f"target: a {self.kind} fault needs a thermocouple {'/'.join(lim.TC_NAMES)}, "
                             f"got {self.target!r}")
        if not on_tc and self.target not in groups:
            raise ValueError(f"target: a {self.kind} fault needs a lamp group of this furnace "
                             f"({', '.join(groups)}), got {self.target!r}")
        r = lim.FAULT_VALUE_RANGE.get(self.kind)
        if r is None and self.value is not None:
            raise ValueError(f"value: a {self.kind} fault takes no value")
        if r is not None:
            if self.value is None:
                raise ValueError(f"value: a {self.kind} fault needs a value ({r.unit or 'fraction kept'})")
            problem = r.problem(self.value)
            if problem is not None:
                raise ValueError(f"value: {problem}")
        return self

    def describe(self) -> str:
        """E.g. 'TC2 drift 0.5 K/s', 'T3h failed'."""
        unit = {"drift": " K/s", "offset": " K", "derate": " kept"}.get(self.kind, "")
        return f"{self.target} {self.kind}" + ("" if self.value is None else f" {self.value:g}{unit}")


class EstimatorChoice(_Model):
    """How the twin estimates (issue 11): the model's motion and whether it calibrates parameters.

    ``motion="averaged", calibrate=False`` is the paper's EKF (section 3.2, eq. 11); the defaults are
    the best measured configuration (docs/estimation.md, campaign).
    """

    motion: Literal["averaged", "position_aware"] = Field(
        "position_aware", description="'averaged' (paper, eq. 11) or 'position_aware' (model at eta(t_j))")
    calibrate: Flag = Field(True, description="learn lamp efficiency and emissivity online (joint EKF)")


#: The paper's estimator, one setting away from the default.
PAPER_ESTIMATOR = EstimatorChoice(motion="averaged", calibrate=False)


class EstimatorSpec(EstimatorChoice):
    """The run's estimator and, optionally, a shadow estimator on the same TC data (shown beside it)."""

    shadow: EstimatorChoice | None = Field(None, description="a second estimator to compare, or null")


class SimulatedPlant(_Model):
    """The run's furnace is simulated in process (``SimulatedFurnace``): any speed."""

    # a plant object names its kind (the discriminator refuses {}); only a left-out plant defaults to this one
    model_config = ConfigDict(json_schema_extra={"required": ["kind"]})

    kind: Literal["simulated"] = "simulated"


#: what ``twin.endpoints.parse_endpoint`` accepts, for the OpenAPI schema: opc.tcp:// (any case), a host, a port
#: up to 65535
ENDPOINT_PATTERN = (r"^\s*[Oo][Pp][Cc]\.[Tt][Cc][Pp]://[A-Za-z0-9._~-]+(:(6553[0-5]|655[0-2][0-9]|65[0-4][0-9]{2}|6[0-4][0-9]{3}|[1-5][0-9]{4}|[0-9]{1,4}))?"
                    r"(/[^\s]*)?\s*$")


class OpcUaPlant(_Model):
    """A furnace over OPC UA (a real one, or ``furnace-twin emulate``): real time only.

    Which endpoints a server may connect to, and with which security, is the server's setting
    (``FURNACE_TWIN_OPCUA_*``), never the scenario's.
    """

    kind: Literal["opcua"]
    endpoint: str = Field("opc.tcp://127.0.0.1:4840/furnace-twin/", max_length=512,
                          description="opc.tcp://host:port/path",
                          json_schema_extra={"pattern": ENDPOINT_PATTERN})

    @field_validator("endpoint")
    @classmethod
    def _endpoint(cls, v: str) -> str:
        from twin.endpoints import parse_endpoint

        return parse_endpoint(v).url


Plant = Annotated[SimulatedPlant | OpcUaPlant, Field(discriminator="kind")]


def _tc4_schema(schema: dict[str, Any]) -> None:
    """OpenAPI: both relative coordinates in [0, 1], as ``Scenario._tc4`` checks."""
    for item in schema.get("prefixItems", []):
        item.update(minimum=lim.TC4_RELATIVE.lo, maximum=lim.TC4_RELATIVE.hi)


def _speed_schema(schema: dict[str, Any]) -> None:
    """OpenAPI: a real-time factor in the range ``Scenario._speed`` checks."""
    for option in schema.get("anyOf", []):
        if option.get("type") == "number":
            option.update(minimum=lim.SPEED.lo, maximum=MAX_SPEED)


class PlanParameters(_Model):
    """Calibrated deviations of the twin's model (relative, 0.05 = 5 % higher) that the plan uses."""

    lamp_efficiency: Num = Field(0.0, ge=-0.5, le=0.5)
    emissivity: Num = Field(0.0, ge=-0.5, le=0.5)
    convection: Num = Field(0.0, ge=-0.5, le=0.5)


class ControlSpec(_Model):
    """The run's feedback on the feedforward plan, and what the plan's model has learnt (docs/control.md)."""

    feedback: Literal["lqg", "mpc"] | None = Field(
        None, description="'lqg': the paper's LQG (eqs. 22-29); 'mpc': the constraint-aware MPC on the same "
        "linearisation; null: the furnace file's [control] feedback")
    plan_parameters: PlanParameters | None = Field(
        None, description="the calibrated deviations the plan and the feasibility check use (a server fills them in "
        "from its furnace's calibration memory); null: the nominal model")


class Scenario(_Model):
    reference: Reference = Field(default_factory=TransitionReference)
    duration: Num = Field(lim.DURATION.default, gt=lim.DURATION.lo, le=lim.DURATION.hi, description="s")
    oscillation: OscillationSpec = Field(default_factory=OscillationSpec)
    tc4: tuple[Num, Num] = Field(_DEFAULT.tc4, description="relative (x / L_s, y / W_s)",
                                 json_schema_extra=_tc4_schema)
    speed: Literal["max"] | Num = Field(lim.SPEED.default, description="'max' or a real-time factor",
                                        json_schema_extra=_speed_schema)
    mismatch: Mismatch = Field(default_factory=Mismatch)
    tc_noise: Num = Field(_DEFAULT.tc_noise.default, ge=0.0, le=lim.TC_NOISE_MAX_K,
                            description="TC noise standard deviation, K")
    seed: Int = Field(lim.SEED.default, ge=lim.SEED.lo, le=lim.SEED.hi)
    faults: list[FaultSpec] = Field(default_factory=list, max_length=lim.MAX_FAULTS,
                                    description="faults injected into the simulated furnace at run time")
    estimator: EstimatorSpec = Field(default_factory=EstimatorSpec)
    truth: lim.TruthKind = Field(
        lim.TRUTH_DEFAULT,
        description="'independent': the simulated furnace differs from the twin's model as its furnace file's "
        "[truth] says (mismatch adds to it); 'shared': the plant on the model's own tables, ideal sensors. "
        "A simulated plant only: a furnace over OPC UA has no truth and ignores it",
    )
    plant: Plant = Field(default_factory=SimulatedPlant, description="the furnace: simulated, or over OPC UA")
    control: ControlSpec = Field(default_factory=ControlSpec, description="the run's feedback")

    @model_validator(mode="before")
    @classmethod
    def _furnace_defaults(cls, data: Any, info: ValidationInfo) -> Any:
        """With a furnace's limits, what is left out takes its defaults (nested models too).  A furnace over
        OPC UA runs at real time: its speed defaults to 1."""
        if isinstance(data, dict) and isinstance(data.get("plant"), dict) and data["plant"].get("kind") == "opcua":
            data = {"speed": 1.0, **data}
        given = _context_limits(info)
        if given is not None and isinstance(data, dict):
            return {"reference": {}, "oscillation": {}, "tc4": given.tc4, "tc_noise": given.tc_noise.default,
                    **data}
        return data

    @model_validator(mode="after")
    def _speed_of_plant(self) -> Scenario:
        if self.plant.kind == "opcua" and self.speed != 1.0:
            raise ValueError(f"speed: a furnace over OPC UA runs in real time; speed must be 1 (got {self.speed!r})")
        if self.plant.kind != "simulated" and self.faults:
            raise ValueError("faults: only the simulated furnace takes injected faults, not one over OPC UA")
        return self

    @field_validator("tc4")
    @classmethod
    def _tc4(cls, v: tuple[float, float]) -> tuple[float, float]:
        r = lim.TC4_RELATIVE
        if r.problem(v[0]) is not None or r.problem(v[1]) is not None:
            raise ValueError("tc4 is relative: both coordinates must lie in [0, 1]")
        return v

    @field_validator("speed")
    @classmethod
    def _speed(cls, v: str | float) -> str | float:
        if isinstance(v, str):
            return v
        if not lim.SPEED.lo <= v <= MAX_SPEED:
            raise ValueError(f"speed must be 'max' or a real-time factor in [{lim.SPEED.lo:g}, {MAX_SPEED:g}]")
        return float(v)

    def to_json(self) -> str:
        return json.dumps(self.model_dump(mode="json"), sort_keys=True)


_REFERENCE: TypeAdapter[Reference] = TypeAdapter(Reference)
_FAULTS: TypeAdapter[list[FaultSpec]] = TypeAdapter(Annotated[list[FaultSpec], Field(max_length=lim.MAX_FAULTS)])


def parse_scenario(data: Any, limits: ScenarioLimits | None = None) -> Scenario:
    """A scenario from JSON data, checked against ``limits`` (default: the default furnace's);
    fields left out take that furnace's defaults.  Raises ``pydantic.ValidationError`` naming each field."""
    return Scenario.model_validate({} if data is None else data, context={"limits": limits or _DEFAULT})


def parse_oscillation(data: Any, limits: ScenarioLimits | None = None) -> OscillationSpec:
    """An oscillation (``PUT .../oscillation``) checked against ``limits``, as :func:`parse_scenario`."""
    return OscillationSpec.model_validate(data, context={"limits": limits or _DEFAULT})


def parse_reference(data: Any, limits: ScenarioLimits | None = None) -> TransitionReference | PointsReference:
    """A reference (``PUT .../reference``) checked against ``limits``, as :func:`parse_scenario`."""
    return _REFERENCE.validate_python(data, context={"limits": limits or _DEFAULT})


def parse_faults(data: Any, limits: ScenarioLimits | None = None) -> list[FaultSpec]:
    """A fault list (``PUT .../faults``) checked against ``limits`` (TC names, the furnace's lamp groups)."""
    return _FAULTS.validate_python(data, context={"limits": limits or _DEFAULT})


def check(value: Scenario | OscillationSpec | TransitionReference | PointsReference, limits: ScenarioLimits) -> None:
    """Raise ``pydantic.ValidationError`` (naming the field) if a scenario, oscillation or reference that was
    built elsewhere (e.g. without a furnace) lies outside ``limits``."""
    data = value.model_dump(mode="json")
    if isinstance(value, Scenario):
        parse_scenario(data, limits)
    elif isinstance(value, OscillationSpec):
        parse_oscillation(data, limits)
    else:
        parse_reference(data, limits)


def describe(value: TransitionReference | PointsReference | OscillationSpec | list[FaultSpec]) -> str:
    """A reference, an oscillation or a list of faults in a few plain words (the run's events, the dashboard).

    >>> describe(TransitionReference(setpoint=1050.0, t_E=30.0)), describe(OscillationSpec())
    ('1050 K in 30 s', 'off')
    >>> describe(PointsReference(points=[(20.0, 1000.0), (60.0, 1050.0)]))
    'points 20 s → 1000 K, 60 s → 1050 K'
    >>> describe([]), describe(parse_faults([{"at": 5.0, "target": "TC2", "kind": "offset", "value": 20.0}]))
    ('no faults', 'TC2 offset 20 K at +5 s')
    """
    if isinstance(value, list):
        return ", ".join(f"{f.describe()} at +{f.at:g} s" for f in value) or "no faults"
    if isinstance(value, OscillationSpec):
        if not value.enabled:
            return "off"
        return f"on ({1000 * value.amplitude:.0f} mm, {value.period:g} s)"
    if isinstance(value, PointsReference):
        pts = [f"{t:g} s → {T:g} K" for t, T in value.points]
        more = f", … ({len(pts)} points)" if len(pts) > 4 else ""
        return "points " + ", ".join(pts[:4]) + more
    return f"{value.setpoint:g} K in {value.t_E:g} s"


def plant_key(scenario: Scenario) -> str:
    """Which plant a run drives (the key of its calibration memory, twin.control.calibration_memory):
    ``simulated-<truth>[-mismatch hash]`` or ``opcua-<endpoint hash>``."""
    plant = scenario.plant
    if plant.kind == "opcua":
        return "opcua-" + hashlib.sha256(plant.endpoint.encode()).hexdigest()[:10]
    mismatch = scenario.mismatch.model_dump()
    tail = "" if not any(mismatch.values()) else "-" + hashlib.sha256(
        json.dumps(mismatch, sort_keys=True).encode()).hexdigest()[:8]
    return f"simulated-{scenario.truth}{tail}"


def plant_label(scenario: Scenario) -> str:
    """The plant in words for the dashboard."""
    plant = scenario.plant
    if plant.kind == "opcua":
        return f"furnace at {plant.endpoint}"
    mismatch = {k: v for k, v in scenario.mismatch.model_dump().items() if v}
    words = "its own truth" if scenario.truth == "independent" else "the model's own tables"
    return f"simulated furnace ({words}{', mismatch ' + str(mismatch) if mismatch else ''})"
