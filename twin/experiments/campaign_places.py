"""One closed loop for all TC4 places of a campaign's (specimen mode, seed): TC4 only validates.

The estimator and the controller use TC1..TC3 only (:data:`twin.furnace.interface.N_ESTIMATOR_TCS`); TC4 is
read, recorded and compared with the estimate at its place, nothing more.  So the campaign's three runs of one
specimen mode and seed that differ only in TC4's place (:data:`twin.experiments.campaign.TC4_POSITIONS`) run the
same loop: the same readings of TC1..TC3, estimates, plans and lamp powers, to the last bit.  They are one run
here: the simulated furnace reads TC4 at the other places too (``SimulatedFurnace(other_tc4=...)``: each with
the noise draw, bias, lag and faults TC4 has in its own run), the loop hands its estimate of each sample to
:class:`TC4Places` (``ClosedLoop(on_estimate=...)``), which reads it at the other places with the
interpolation rows a run with TC4 there uses, and each other place becomes a :class:`PlaceLoop`: the shared
run's samples with TC4's reading, status and estimate at that place, which a
:class:`twin.runs.session.RunSession` writes into the place's run folder as it writes any run.

What a run's TC4 could change besides its own series, and why it does not here (:func:`shares_loop`):

- the fault detection's reading tests screen TC4 too and report ("TC4 ... stuck") without acting: a stuck
  report needs ``flat_s`` of readings within ``flat_tolerance`` (1e-6 K) of each other, which TC noise
  (``tc_noise`` > 0, required) rules out, and a dropout needs an injected fault (no faults, required);
- the divergence guard compares TC1..TC3 only (and needs the estimate at the TCs finite, as it is at any place
  when the estimate is finite);
- live changes and events of a host would have to be replayed: a shared run that has any changes falls back
  (:meth:`TC4Places.loops` refuses, the caller runs the places alone).

``tests/experiments/test_campaign_places.py`` compares a shared run's places with runs of TC4 there alone.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from concurrent.futures import Future
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.events import RunEvent
from twin.furnace.simulated import SimulatedFurnace
from twin.furnace.simulated.thermocouples import Thermocouples
from twin.runs.loop import ClosedLoop
from twin.runs.outage import run_ending
from twin.runs.record import RunRecord, Snapshot
from twin.runs.series_store import SeriesStore, append_series
from twin.scenario import FaultSpec, OscillationSpec, Reference, Scenario

Array = NDArray[np.float64]


class SharedRunRefused(RuntimeError):
    """The shared run did something its places cannot replay (a live change, a host's event)."""


def shares_loop(scenarios: Sequence[Scenario]) -> bool:
    """Runs of these scenarios can be one run with TC4 at each one's place (module docstring): a simulated
    plant, the same scenario but for TC4, no injected faults, TC noise."""
    first = scenarios[0]
    same = first.model_copy(update={"tc4": (0.0, 0.0)}).to_json()
    return (first.plant.kind == "simulated" and not first.faults and first.tc_noise > 0.0
            and all(s.model_copy(update={"tc4": (0.0, 0.0)}).to_json() == same for s in scenarios))


class TC4Places:
    """The other TC4 places of a shared run: their readings and estimates per sample, then their loops.

    Build the furnace with ``other_tc4=places.places``, the loop with ``on_estimate=places.on_estimate``, call
    :meth:`attach` with the loop, run it with :meth:`sink` among its sinks, then :meth:`loops`.
    """

    def __init__(self, cfg: FurnaceConfig, scenarios: Sequence[Scenario]) -> None:
        self.scenarios = list(scenarios)
        self.places = [tuple(s.tc4) for s in self.scenarios]
        #: (4, 2) m per place, as the simulated furnace with TC4 there has them (its ``tc_positions``)
        self.positions = [Thermocouples(cfg, cfg.tc_positions(p)).positions for p in self.places]  # type: ignore[arg-type]
        self._phi: list[Array] = []
        self._loop: ClosedLoop | None = None
        self._furnace: SimulatedFurnace | None = None
        self._pending: list[dict[str, Any]] = []
        self.snapshots: list[list[Snapshot]] = [[] for _ in self.places]

    def attach(self, loop: ClosedLoop) -> None:
        """The shared loop (built with :meth:`on_estimate`, before its first step): the estimate is read at each
        place with the rows of the first plan's model, as the loop reads it at its own TCs."""
        if not isinstance(loop.furnace, SimulatedFurnace):
            raise TypeError("the TC4 places need the simulated furnace")
        self._loop, self._furnace = loop, loop.furnace
        fe = loop.changes.current.model.fe
        self._phi = [np.asarray(fe.phi(np.asarray(pos, float)), float) for pos in self.positions]

    def on_estimate(self, theta: Array, shadow: Array | None) -> None:
        """``ClosedLoop(on_estimate=...)``: this sample's readings and estimates at the other places."""
        if self._furnace is None or self._loop is None:
            raise RuntimeError("TC4Places.attach(loop) before the first step")
        readings = self._furnace.other_tc4_readings(self._loop.sample_time())
        self._pending = [{"tc": np.where(r.usable, r.values, np.nan), "tc_status": tuple(r.status),
                          "tc_hat": phi @ theta, "shadow_tc_hat": None if shadow is None else phi @ shadow}
                         for r, phi in zip(readings, self._phi, strict=True)]

    def sink(self, out: Path, loop: Any) -> _Collector:
        """A sink factory (``execute_run(sink_factories=...)``) that keeps each sample for the places."""
        return _Collector(self)

    def add(self, snap: Snapshot) -> None:
        if len(self._pending) != len(self.places):
            raise RuntimeError("a snapshot without the TC4 places' readings (TC4Places.on_estimate not called)")
        for kept, fields in zip(self.snapshots, self._pending, strict=True):
            kept.append(dataclasses.replace(snap, **fields))
        self._pending = []

    def loops(self) -> list[PlaceLoop]:
        """One loop per place, replaying the shared run's samples with TC4 there; raises
        :class:`SharedRunRefused` when the shared run had live changes or events of a host."""
        loop = self._loop
        if loop is None:
            raise RuntimeError("TC4Places.attach(loop) first")
        if loop.record.n_changes:
            raise SharedRunRefused("the shared run had live changes")
        said = sum(len(s.events) for s in self.snapshots[0]) if self.snapshots else 0
        if loop.record.n_events != said:
            raise SharedRunRefused("the shared run had events of its host")
        return [PlaceLoop(loop, s, pos, snaps) for s, pos, snaps in
                zip(self.scenarios, self.positions, self.snapshots, strict=True)]


class _Collector:
    """The shared run's sink that hands each snapshot to :class:`TC4Places`."""

    def __init__(self, places: TC4Places) -> None:
        self._places = places

    def add(self, snap: Any) -> None:
        self._places.add(snap)

    def flush(self) -> None:
        return None

    def close(self) -> None:
        return None


class PlaceLoop:
    """A :class:`twin.runs.interface.Loop` of one other TC4 place: the shared run's samples replayed with TC4's
    reading, status and estimate there, into a record of its own (its header: this place's TC positions and
    scenario), as the loop of a run with TC4 there records them.  It takes no live changes."""

    paced_by_furnace = False
    replanning = False

    def __init__(self, shared: ClosedLoop, scenario: Scenario, tc_positions: Array, snapshots: list[Snapshot]
                 ) -> None:
        self.scenario = scenario
        self.t_s = shared.t_s
        self.tc_positions = np.asarray(tc_positions, float)
        self._shared = shared
        self._snapshots = snapshots
        rec = shared.record  # no live changes (TC4Places.loops): its full_rate_until is still the first one
        header = dataclasses.replace(rec.header, tc_positions=self.tc_positions, scenario=scenario.to_json())
        self.record = RunRecord(header, has_truth=rec.has_truth, field_every=rec.field_every,
                                full_rate_until=rec.full_rate_until, capacity=rec.capacity)
        self.j = 0
        self._series: SeriesStore | None = None

    @property
    def done(self) -> bool:
        return self.j >= len(self._snapshots)

    def step(self) -> Snapshot:
        if self.done:
            raise StopIteration("run finished")
        snap = self._snapshots[self.j]
        self.record.append(snap)
        self.j += 1
        return snap

    def ending(self, end: str, error: str | None = None) -> tuple[str, str | None]:
        """As the shared loop's (its TC1..TC3 decide whether the run ended blind)."""
        return run_ending(end, error, self._shared.blindness, max(self.j - 1, 0) * self.t_s)

    def timeseries(self) -> dict[str, Any]:
        return self.record.arrays()

    def metrics(self) -> dict[str, Any]:
        return self.record.metrics()

    def add_event(self, event: RunEvent) -> None:
        self.record.add_event(event)

    def append_series(self, folder: Path) -> None:
        """As ``ClosedLoop.append_series``."""
        self._series = append_series(self._series, folder, self.record)

    def _no_changes(self) -> Any:
        raise ValueError("a TC4 place of a shared campaign run replays it: it takes no live changes")

    def set_reference(self, ref: Reference) -> Future[float] | None:
        return self._no_changes()  # type: ignore[no-any-return]

    def set_oscillation(self, spec: OscillationSpec) -> Future[float] | None:
        return self._no_changes()  # type: ignore[no-any-return]

    def set_faults(self, faults: list[FaultSpec]) -> None:
        self._no_changes()

    def close(self) -> None:
        self._snapshots = []


if TYPE_CHECKING:  # mypy holds a place to what a run session asks of a loop
    from twin.runs.interface import Loop

    _A_PLACE_IS_A_LOOP: type[Loop] = PlaceLoop
