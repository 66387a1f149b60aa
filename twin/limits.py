"""Scenario limits and defaults of a furnace: the one place they are derived (product.md).

Every bound and default of a run's scenario (``twin.scenario``) is a :class:`Range` of
:class:`ScenarioLimits`.  Most are fixed by what the twin supports (run length, speed,
plant mismatch); the others come from the loaded furnace:

- oscillation amplitude in [0, eta_max] (the exchange factors are tabulated only there),
  default the paper's 3 L_h (section 5.2: eta = 3 L_h sin(2 pi t / Pi)) capped at eta_max;
- period default 0.15 t_E (section 5.2: Pi = 0.15 t_E) with the paper's t_E = 120 s;
- setpoint above the specimen's initial temperature and at most the top of the material
  tables (beyond it c_p and lambda would be extrapolated), default the paper's 1100 K;
- reference point temperatures in that same range (one set of limits for every reference; a point
  may equal the initial temperature, a setpoint must lie above it);
- TC4 position and TC noise default to the furnace's ``[sensors]``;
- injected faults name a TC (TC1..TC4) or one of the furnace's lamp groups.

The backend reports them (``GET /api/furnace``) and both UIs build their inputs from them;
``twin.scenario.parse_scenario`` checks a scenario against them and fills what is left out.

Example
-------
>>> from twin.config import small_config
>>> low = scenario_limits(small_config().with_overrides({"oscillation.eta_max": 0.03}))
>>> low.amplitude.hi, low.amplitude.default, low.amplitude.problem(0.048)
(0.03, 0.03, "at most 0.03 m (eta_max of furnace 'custom'), got 0.048 m")
"""

from __future__ import annotations

import dataclasses
import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from twin.config import DEFAULT_CONFIG_PATH, SHIPPED_FURNACES, FurnaceConfig, load_config

# the paper's experiment (section 5): the defaults wherever the furnace allows them
PAPER_SETPOINT_K = 1100.0
PAPER_T_E_S = 120.0
PAPER_PERIOD_PER_T_E = 0.15  # Pi = 0.15 t_E
PAPER_AMPLITUDE_PITCHES = 3.0  # eta amplitude 3 L_h

MAX_DURATION_S = 3600.0  # longest run and latest reference point the twin accepts
#: most reference points a scenario or a live change may hold: a C1 curve over at most MAX_DURATION_S needs
#: no more (one point every 3.6 s), and it bounds the body, the stored scenario and every list of runs
MAX_REFERENCE_POINTS = 1000


@dataclass(frozen=True)
class Range:
    """A closed interval [lo, hi] (or (lo, hi] with ``lo_open``) with its default and unit."""

    lo: float
    hi: float
    default: Any = None
    unit: str = ""
    lo_open: bool = False
    why: str = ""  # what fixes hi, in the message of a value above it

    def problem(self, value: float) -> str | None:
        """``None`` if ``value`` lies in the range, else a sentence that says the bound."""
        unit = f" {self.unit}" if self.unit else ""
        why = f" ({self.why})" if self.why else ""
        if value > self.hi:
            return f"at most {self.hi:g}{unit}{why}, got {value:g}{unit}"
        if value < self.lo or (self.lo_open and value == self.lo):
            return f"{'above' if self.lo_open else 'at least'} {self.lo:g}{unit}, got {value:g}{unit}"
        return None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"min": self.lo, "max": self.hi, "exclusive_min": self.lo_open, "unit": self.unit}
        if self.default is not None:
            out["default"] = list(self.default) if isinstance(self.default, tuple) else self.default
        return out


# ranges fixed by the twin (the same for every furnace)
T_E = Range(1.0, MAX_DURATION_S, PAPER_T_E_S, "s", lo_open=True)
DURATION = Range(0.0, MAX_DURATION_S, 2 * PAPER_T_E_S, "s", lo_open=True)
POINT_TIME = Range(0.0, MAX_DURATION_S, None, "s")
POINT_COUNT = Range(1, MAX_REFERENCE_POINTS, None, "points")
PERIOD = Range(1.0, 600.0, PAPER_PERIOD_PER_T_E * PAPER_T_E_S, "s")
SPEED = Range(0.01, 1000.0, "max", "x real time")
#: Largest TC noise (standard deviation, K) the estimator is shown to follow (issue 15, finding 2): on the
#: small furnace, 40 s runs to 1000 K, seeds 0 and 1, its fillet mean stayed within 16 K of the plant's at
#: 5 K, 33 K at 7 K, and at 8 K one seed diverged (stopped by twin.runs.guards) and the other was 139 K off;
#: at 10 K both ran off to NaN.  tests/runs/test_hardening_estimator.py checks the whole range.
TC_NOISE_MAX_K = 5.0
TC4_RELATIVE = Range(0.0, 1.0, None, "")
MISMATCH_EMISSIVITY = Range(-0.5, 0.1, 0.0)
MISMATCH_ALPHA = Range(-0.9, 2.0, 0.0)
MISMATCH_LAMP_EFFICIENCY = Range(-0.5, 0.5, 0.0)
SEED = Range(0, 2**31 - 1, 0)
# injected faults (simulated furnace only): onset time, and the size of each kind that takes a value
FAULT_AT = Range(0.0, MAX_DURATION_S, 0.0, "s")
FAULT_DRIFT = Range(-50.0, 50.0, None, "K/s")
FAULT_OFFSET = Range(-500.0, 500.0, None, "K")
FAULT_DERATE = Range(0.0, 1.0, None, "")  # fraction of the group's power kept
MAX_FAULTS = 32  # entries of one fault list
TC_NAMES = ("TC1", "TC2", "TC3", "TC4")
TC_FAULT_KINDS = ("stuck", "drift", "offset", "dropout")
GROUP_FAULT_KINDS = ("failed", "derate")
#: the size a fault kind takes (the others take none)
FAULT_VALUE_RANGE = {"drift": FAULT_DRIFT, "offset": FAULT_OFFSET, "derate": FAULT_DERATE}

#: the simulated furnace's truth (twin.scenario.Scenario.truth): its own, or the model's tables and ideal sensors
TruthKind = Literal["independent", "shared"]
TRUTH_CHOICES: tuple[TruthKind, ...] = ("independent", "shared")
TRUTH_DEFAULT: TruthKind = "independent"


@dataclass(frozen=True)
class ScenarioLimits:
    """Every scenario bound and default for one furnace (built by :func:`scenario_limits`)."""

    furnace: str
    setpoint: Range
    point_temperature: Range
    amplitude: Range
    tc4: tuple[float, float]
    tc_noise: Range
    groups: tuple[str, ...] = ()  # lamp group names, in the order of u (targets of lamp faults)
    t_E: Range = T_E
    point_time: Range = POINT_TIME
    point_count: Range = POINT_COUNT
    duration: Range = DURATION
    period: Range = PERIOD
    speed: Range = SPEED
    mismatch_emissivity: Range = MISMATCH_EMISSIVITY
    mismatch_alpha: Range = MISMATCH_ALPHA
    mismatch_lamp_efficiency: Range = MISMATCH_LAMP_EFFICIENCY
    seed: Range = SEED

    def capped(self, max_duration_s: float, max_speed: float) -> ScenarioLimits:
        """The same limits within a server's run length and speed (``backend.core.settings``)."""
        d, s = self.duration, self.speed
        return dataclasses.replace(
            self,
            duration=dataclasses.replace(d, hi=min(d.hi, max_duration_s), default=min(d.default, max_duration_s),
                                         why="this server's limit" if max_duration_s < d.hi else d.why),
            speed=dataclasses.replace(s, hi=min(s.hi, max_speed),
                                      why="this server's limit" if max_speed < s.hi else s.why),
        )

    def to_json(self) -> dict[str, Any]:
        """The limits in the shape of a scenario (``GET /api/furnace``)."""
        tc4 = [dataclasses.replace(TC4_RELATIVE, default=v).to_json() for v in self.tc4]
        return {
            "reference": {"setpoint": self.setpoint.to_json(), "t_E": self.t_E.to_json(),
                          "points": {"time": self.point_time.to_json(),
                                     "temperature": self.point_temperature.to_json(),
                                     "count": self.point_count.to_json()}},
            "duration": self.duration.to_json(),
            "oscillation": {"amplitude": self.amplitude.to_json(), "period": self.period.to_json()},
            "tc4": {"x": tc4[0], "y": tc4[1]},
            "speed": self.speed.to_json(),
            "mismatch": {"emissivity": self.mismatch_emissivity.to_json(), "alpha": self.mismatch_alpha.to_json(),
                         "lamp_efficiency": self.mismatch_lamp_efficiency.to_json()},
            "tc_noise": self.tc_noise.to_json(),
            "seed": self.seed.to_json(),
            "faults": {"at": FAULT_AT.to_json(), "targets": {"tc": list(TC_NAMES), "group": list(self.groups)},
                       "kinds": {"tc": list(TC_FAULT_KINDS), "group": list(GROUP_FAULT_KINDS)},
                       "drift": FAULT_DRIFT.to_json(), "offset": FAULT_OFFSET.to_json(),
                       "derate": FAULT_DERATE.to_json(), "max_entries": MAX_FAULTS},
            "truth": {"choices": list(TRUTH_CHOICES), "default": TRUTH_DEFAULT},
        }


def scenario_limits(cfg: FurnaceConfig, name: str | None = None) -> ScenarioLimits:
    """Derive every scenario limit and default from ``cfg`` (see the module docstring)."""
    name = name or furnace_name(cfg)
    eta_max = cfg.oscillation.eta_max
    T_0 = cfg.specimen.initial_temperature
    T_top = cfg.material.temperatures[-1]
    top = "top of the furnace's material tables"
    return ScenarioLimits(
        furnace=name,
        setpoint=Range(T_0, T_top, min(PAPER_SETPOINT_K, T_top), "K", lo_open=True, why=top),
        point_temperature=Range(T_0, T_top, None, "K", why=top),  # a first point may be the initial temperature
        amplitude=Range(0.0, eta_max, min(PAPER_AMPLITUDE_PITCHES * cfg.lamps.horizontal.pitch, eta_max), "m",
                        why=f"eta_max of furnace '{name}'"),
        tc4=cfg.sensors.tc4,
        tc_noise=Range(0.0, TC_NOISE_MAX_K, cfg.sensors.noise, "K"),
        groups=tuple(g.name for g in cfg.lamps.groups),
    )


def furnace_name(cfg: FurnaceConfig, source: str | os.PathLike[str] | None = None) -> str:
    """A label for the furnace: the shipped name or file stem of ``source`` (``--config``), else the
    shipped furnace ``cfg`` is equal to, else ``"custom"``."""
    if source is not None:
        return str(source) if str(source) in SHIPPED_FURNACES else Path(source).stem
    digest = cfg.digest()
    return next((name for name, path in SHIPPED_FURNACES.items() if _digest_of(path) == digest), "custom")


@functools.cache
def _digest_of(path: Path) -> str:
    return load_config(path).digest()


@functools.cache
def default_limits() -> ScenarioLimits:
    """The limits of the default furnace: what a scenario built without a furnace is checked against."""
    return scenario_limits(load_config(DEFAULT_CONFIG_PATH), "default")
