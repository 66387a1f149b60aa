"""The furnace boundary: what the twin talks to (architecture.md, "a furnace and a twin").

The loop (:mod:`twin.runs.loop`) sees a furnace only through :class:`Furnace`.  Per sample
t_j = j t_s it

1. reads the thermocouples of sample t_j (:meth:`Furnace.read`): a value, a source timestamp
   and a status per TC;
2. lets the estimator and the controller compute the group powers u_j;
3. applies them (:meth:`Furnace.apply`): held until the next sample (zero-order hold).

:meth:`Furnace.motion` reports the specimen's position and the drive's settings,
:meth:`Furnace.set_oscillation` commands the drive.  A simulated furnace
(:class:`twin.furnace.simulated.SimulatedFurnace`: plant, sensors, motion) also has a true
field (:meth:`Furnace.true_field`); a real one (over OPC UA) returns ``None`` there, and
everything downstream (metrics, stream, recording, both UIs) handles its absence.

A simulated furnace keeps no clock of its own: it moves on when the loop applies the next input, so a run
goes as fast as the loop (or as a speed paces it).  A real-time furnace (:attr:`Furnace.realtime`, e.g.
:class:`twin.furnace.opcua.OpcUaFurnace`) has its own clock: :meth:`Furnace.read` waits for the sample,
and one that comes too late is ``missing``.  Its first ``read(0.0)`` after the loop is set up starts
the run's clock.  A furnace that cannot be reached any more raises :class:`FurnaceLost`.

The twin's side (``twin.model``, ``twin.estimation``, ``twin.control``) never imports an
implementation: it gets readings and gives powers.

Example
-------
>>> import numpy as np
>>> r = Readings(values=np.array([900.0, np.nan, 905.0, 910.0]), timestamps=np.zeros(4),
...              status=("good", "missing", "good", "good"))
>>> r.usable.tolist(), r.for_estimator().tolist()
([True, False, True, True], [900.0, nan, 905.0])
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from twin.scenario import FaultSpec, OscillationSpec

Array = NDArray[np.float64]

#: "good": a fresh reading of this sample; "bad": the sensor reports a fault (value not usable);
#: "missing": no reading arrived for this sample (late or lost); "unlinked": none could arrive, the link to the
#: furnace being down or this TC's subscription on a new connection not delivering yet (a real-time furnace:
#: :func:`twin.furnace.opcua.furnace.unlinked_channels`); the fault detection does not count it against the TC.
TCStatus = Literal["good", "bad", "missing", "unlinked"]
N_ESTIMATOR_TCS = 3  # TC1..TC3 feed the EKF; TC4 only validates (paper section 3.2)


class FurnaceLost(RuntimeError):
    """The furnace cannot be reached any more (its link was not restored in time); the run ends ``plant_lost``."""


@dataclass(frozen=True)
class Readings:
    """The thermocouples TC1..TC4 of one sample.

    Attributes
    ----------
    values : (4,) K; NaN where the status is not "good"
    timestamps : (4,) s of run time at which each reading was taken (the source timestamp)
    status : one :data:`TCStatus` per TC
    """

    values: Array
    timestamps: Array
    status: tuple[TCStatus, ...]

    @property
    def usable(self) -> NDArray[np.bool_]:
        """Which readings carry a good, finite value."""
        good = np.array([s == "good" for s in self.status])
        return good & np.isfinite(self.values)

    def for_estimator(self) -> Array:
        """TC1..TC3 as the EKF takes them: NaN where a reading is not usable (it is then left out)."""
        y = np.where(self.usable, self.values, np.nan)
        return y[:N_ESTIMATOR_TCS]


@dataclass(frozen=True)
class Motion:
    """The specimen's position and the drive's settings at one time.

    eta(t) = amplitude sin(2 pi (t - since) / period) while ``oscillation.enabled``, else 0.
    """

    eta: float  # m
    oscillation: OscillationSpec
    since: float  # s of run time at which these settings took effect


@runtime_checkable
class Furnace(Protocol):
    """A furnace the twin can run: read TCs, apply group powers, report and command the motion."""

    @property
    def kind(self) -> str:
        """"simulated" or the kind of the connection (e.g. "opcua")."""
        ...

    @property
    def t_s(self) -> float:
        """The sample time (s) of reads and applies."""
        ...

    @property
    def realtime(self) -> bool:
        """The furnace runs on its own clock: :meth:`read` waits for the sample, and runs go at real time."""
        ...

    @property
    def tc_positions(self) -> Array:
        """(4, 2) absolute positions (m) of TC1..TC4 on the specimen."""
        ...

    def read(self, t: float) -> Readings:
        """The readings of sample time ``t`` (s of run time)."""
        ...

    def apply(self, u: Array, t: float) -> None:
        """Hold the group powers u (fractions of u_max, order of the furnace's groups) from ``t`` on."""
        ...

    def motion(self, t: float) -> Motion:
        """The specimen position and drive settings at run time ``t``."""
        ...

    def set_oscillation(self, spec: OscillationSpec, t: float) -> None:
        """Command the specimen drive from run time ``t`` on (the motion restarts at eta = 0)."""
        ...

    def true_field(self) -> Array | None:
        """The true cell temperatures (N_s,) K at the last read sample; ``None`` if unknown (a real furnace)."""
        ...

    def drain_events(self) -> tuple[str, ...]:
        """What the furnace reported since the last call (a link lost or restored), for the run's events."""
        ...

    def close(self) -> None:
        """Release the furnace (a real one: lamps commanded off where the link allows)."""
        ...


def delivered(furnace: Furnace, u: Array, t: float) -> Array:
    """The group powers the furnace is believed to hold from run time ``t`` when the twin commanded ``u``: the
    furnace's own account if it keeps one (``delivered(u, t)``: a furnace over OPC UA that the twin cannot reach
    holds none once its watchdog has switched the lamps off), else ``u``."""
    own = getattr(furnace, "delivered", None)
    return np.asarray(own(u, t) if callable(own) else u, float)


@runtime_checkable
class FaultInjectable(Protocol):
    """A furnace that faults can be injected into (the simulated one: :mod:`twin.furnace.simulated.faults`).

    Only the loop uses it, to pass the scenario's and the user's faults on and to record when they
    start; the twin (estimator, detector, controller) never sees it.
    """

    def set_faults(self, faults: Sequence[FaultSpec], t: float) -> None:
        """Replace the injected faults from run time ``t`` on (their ``at`` counted from ``t``)."""
        ...

    def faults_in_force(self) -> list[FaultSpec]:
        """The injected faults, ``at`` in run time."""
        ...

    def take_fault_events(self) -> list[str]:
        """Faults that started or were cleared since the last call, as sentences."""
        ...
