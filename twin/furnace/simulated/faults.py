"""Faults injected into the simulated furnace: what its thermocouples report and what its lamp groups deliver.

A :class:`FaultInjector` sits between the plant and the furnace boundary of
:class:`twin.furnace.simulated.SimulatedFurnace`.  From a fault's onset ``at`` (s of run time) on

- a TC ``stuck`` repeats the value it reported at the onset (status "good": a frozen transmitter
  does not know it is frozen);
- a TC ``drift`` adds ``value`` (t - at) K, an ``offset`` adds ``value`` K;
- a TC ``dropout`` reports no value (NaN, status "bad": an open thermocouple);
- a lamp group ``failed`` delivers no power whatever it is commanded;
- a lamp group ``derate`` delivers the fraction ``value`` of its commanded power.

Faults on one target act in list order (an offset listed before ``stuck`` is frozen with it).  The
twin never sees this module: it gets the faulty readings and must find out by itself
(:mod:`twin.estimation.fault_detection`).

Example
-------
>>> import numpy as np
>>> from twin.scenario import FaultSpec
>>> inj = FaultInjector(("T1h", "T2h"), [FaultSpec(at=1.0, target="TC2", kind="offset", value=5.0),
...                                      FaultSpec(at=0.0, target="T2h", kind="failed")])
>>> inj.readings(0.0, np.array([300.0, 300.0, 300.0, 300.0]))[0].tolist()
[300.0, 300.0, 300.0, 300.0]
>>> inj.readings(1.0, np.array([300.0, 300.0, 300.0, 300.0]))[0].tolist()
[300.0, 305.0, 300.0, 300.0]
>>> inj.delivered(0.0, np.array([0.5, 0.5])).tolist()
[0.5, 0.0]
>>> inj.take_events()
['fault injected: T2h failed at t = 0.0 s', 'fault injected: TC2 offset 5 K at t = 1.0 s']
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from twin.furnace.interface import TCStatus
from twin.limits import TC_NAMES
from twin.scenario import FaultSpec

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

#: a fault is in force from the first sample at or after its onset (times within this of each other are equal)
TIME_TOLERANCE_S = 1e-9


@dataclass
class _Scheduled:
    spec: FaultSpec  # ``at`` in absolute run time
    started: bool = False
    stuck_value: float | None = None


@dataclass
class FaultInjector:
    """The faults of one simulated furnace (module docstring).

    Parameters
    ----------
    groups : the furnace's lamp group names, in the order of u
    faults : the scenario's faults (``at`` in run time)
    """

    groups: tuple[str, ...]
    faults: Sequence[FaultSpec] = ()
    _scheduled: list[_Scheduled] = field(init=False, default_factory=list)
    _events: list[str] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        self.schedule(self.faults, 0.0)

    def schedule(self, faults: Sequence[FaultSpec], t_now: float) -> None:
        """Replace every fault by ``faults``, their ``at`` counted from ``t_now`` (an empty list clears them)."""
        unknown = [f.target for f in faults if f.target not in TC_NAMES and f.target not in self.groups]
        if unknown:
            raise ValueError(f"no TC or lamp group named {', '.join(unknown)} in this furnace")
        cleared = [s.spec for s in self._scheduled if s.started]
        self._scheduled = [_Scheduled(f.model_copy(update={"at": float(t_now) + f.at})) for f in faults]
        if cleared:
            self._events.append(f"faults cleared at t = {t_now:.1f} s: {', '.join(f.describe() for f in cleared)}")

    def in_force(self) -> list[FaultSpec]:
        """Every scheduled fault (``at`` in run time), started or not."""
        return [s.spec for s in self._scheduled]

    def _active(self, t: float) -> list[_Scheduled]:
        out = []
        for s in self._scheduled:
            if t + TIME_TOLERANCE_S >= s.spec.at:
                if not s.started:
                    s.started = True
                    self._events.append(f"fault injected: {s.spec.describe()} at t = {t:.1f} s")
                    log.info("fault injected: %s at t = %.1f s", s.spec.describe(), t)
                out.append(s)
        return out

    def readings(self, t: float, values: Array) -> tuple[Array, tuple[TCStatus, ...]]:
        """What TC1..TC4 report at sample time t, from the true readings ``values`` (K)."""
        out = np.array(values, dtype=float)
        status: list[TCStatus] = ["good"] * len(out)
        for s in self._active(t):
            f = s.spec
            if f.target not in TC_NAMES:
                continue
            i = TC_NAMES.index(f.target)
            if f.kind == "offset":
                out[i] += float(f.value or 0.0)
            elif f.kind == "drift":
                out[i] += float(f.value or 0.0) * (t - f.at)
            elif f.kind == "stuck":
                if s.stuck_value is None:
                    s.stuck_value = float(out[i])
                out[i] = s.stuck_value
            elif f.kind == "dropout":
                out[i] = np.nan
                status[i] = "bad"
        return out, tuple(status)

    def delivered(self, t: float, u: Array) -> Array:
        """The group powers the lamps deliver over [t, t + t_s] when commanded ``u`` (fractions of u_max)."""
        kept = np.ones(len(self.groups))
        for s in self._active(t):
            f = s.spec
            if f.target in self.groups:
                kept[self.groups.index(f.target)] *= 0.0 if f.kind == "failed" else float(f.value or 0.0)
        if np.all(kept == 1.0):
            return np.asarray(u, dtype=float)
        return np.clip(np.asarray(u, dtype=float), 0.0, 1.0) * kept

    def take_events(self) -> list[str]:
        """What happened since the last call (faults started, cleared), oldest first."""
        events, self._events = self._events, []
        return events
