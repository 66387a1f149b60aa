"""What a host (the CLI, a study worker, the server) may ask of a run's closed loop: the :class:`Loop` protocol.

Two classes implement it: ``twin.runs.loop.ClosedLoop`` (in this process) and
``backend.runs.process_loop.ProcessLoop`` (the same loop in a child process, one pipe round trip a call);
the server's test stand-in (``tests/backend/conftest.py::FakeLoop``) too.  A host calls these members and no
others, so a loop in another process or a stand-in needs nothing more.  In the do-mpc spirit, one verb
advances everything: :meth:`Loop.step` reads the furnace, estimates, controls and records one sample.
"""

from __future__ import annotations

from concurrent.futures import Future
from pathlib import Path
from typing import Any, Protocol

from twin.events import RunEvent
from twin.scenario import FaultSpec, OscillationSpec, Reference, Scenario


class Loop(Protocol):
    """One run's closed loop, as its host drives it."""

    scenario: Scenario  #: the scenario the loop was built for
    t_s: float  #: the sampling period (s)

    @property
    def done(self) -> bool:
        """The scenario's duration is reached (or the furnace said the run is over)."""
        ...

    @property
    def paced_by_furnace(self) -> bool:
        """A real-time furnace: :meth:`step` waits for its next sample, the host does not pace the run."""
        ...

    @property
    def replanning(self) -> bool:
        """A re-plan of a live change is being solved (at speed max the host waits for it)."""
        ...

    def step(self) -> Any:
        """One sample: the snapshot (``twin.runs.record.Snapshot``), already in the run record."""
        ...

    def set_reference(self, ref: Reference) -> Future[float] | None:
        """Plan a new reference; the future gives the run time from which it is in force (``None``: at once)."""
        ...

    def set_oscillation(self, spec: OscillationSpec) -> Future[float] | None:
        """Plan a new oscillation; as :meth:`set_reference`."""
        ...

    def set_faults(self, faults: list[FaultSpec]) -> None:
        """Inject faults from the next sample on; ``ValueError`` for a furnace that cannot take them."""
        ...

    def add_event(self, event: RunEvent) -> None:
        """An event of the host's (a change's outcome, the run's end) into the run record."""
        ...

    def append_series(self, folder: Path) -> None:
        """Append the samples since the last call to the run's series parts in ``folder``
        (``twin.runs.series_store``)."""
        ...

    def timeseries(self) -> dict[str, Any]:
        """Everything recorded so far, in the ``timeseries.npz`` layout."""
        ...

    def metrics(self) -> dict[str, Any]:
        """The run's metrics so far (``twin.runs.metrics``); NaN where a window was not reached."""
        ...

    def ending(self, end: str, error: str | None = None) -> tuple[str, str | None]:
        """The run's status and its reason for the host's ``end`` (``twin.runs.outage.run_ending``)."""
        ...

    def close(self) -> None:
        """Release the furnace and any planning thread or process; idempotent."""
        ...
