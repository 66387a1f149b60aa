"""What the loop does about the faults its detector finds (``twin.runs.loop.ClosedLoop``; docs/faults.md).

- :func:`innovation_tests_wanted`: the detector's innovation tests run while the estimator's model can
  explain its innovations: once the reference has held still for :data:`SETTLED_S`.  While the furnace
  heats the model's errors are largest (against the simulated furnace's own truth, issue 10: 7-11 % of the
  setpoint open loop in the transient, 4-5 % in the steady state) and its innovations pass for faults: a
  fault-free heat-up of the small furnace had T2v declared failed at 25 s; with the averaged model (eq. 11)
  of an oscillating specimen every heat-up raised false decisions even against the model's own plant;
- :func:`faulty_model`: the controller's model with each lamp group scaled by the fraction of its power it
  is believed to deliver (a failed group's column of B is 0: the OCP holds it at 0, the LQG leaves it);
- :func:`reach_note`: what the groups left can hold (fillet mean at full power, the model's steady state)
  against the reference, for the event of the re-plan;
- :class:`FaultRideThrough`: the loop's collaborator for it (switching the innovation tests, reporting the
  detector's decisions, asking for a plan when a lamp group's state changed, injecting faults).

Example
-------
>>> innovation_tests_wanted(t=130.0, t_end=120.0), innovation_tests_wanted(t=140.0, t_end=120.0)
(False, True)
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.furnace.interface import FaultInjectable, Furnace
from twin.scenario import FaultSpec

log = logging.getLogger(__name__)

#: the innovation tests wait this long (s) after the reference's transition (docs/faults.md: false
#: decisions during heat-ups, at 52-64 s of every oscillating one and at 25 s of a fixed one against the truth)
SETTLED_S = 20.0


def innovation_tests_wanted(t: float, t_end: float) -> bool:
    """See the module docstring: at run time ``t`` with a reference whose transition ends at ``t_end``."""
    return t >= t_end + SETTLED_S


def detection_mode_event(on: bool) -> str:
    """The event that says when the innovation tests switch."""
    if on:
        return "fault detection: innovation tests on (reference held still)"
    return ("fault detection: while the reference moves the model cannot explain the TCs sample by sample: "
            "only TCs that drop out or stick are detected")


class LampReplanner(Protocol):
    """What :class:`FaultRideThrough` asks of the loop's plans (``twin.runs.live_changes.LiveChanges``)."""

    def lamps_found(self, lamp_gains: NDArray[np.float64], what: str, t: float) -> Future[float]:
        """Re-plan with the lamp groups believed to deliver ``lamp_gains`` of their power."""
        ...


def faulty_model(nominal: Any, lamp_gains: ArrayLike) -> Any:
    """The discrete model (12a) with input column i of B scaled by lamp_gains[i] (the nominal one if all 1)."""
    g = np.asarray(lamp_gains, float)
    return nominal if np.all(g == 1.0) else dataclasses.replace(nominal, B=nominal.B * g[None, :])


def reach_note(cfg: FurnaceConfig, model: Any, lamp_gains: ArrayLike, T_end: float) -> str:
    """E.g. "with T2h failed the groups left hold up to 1374 K: the reference (1100 K) stays reachable"."""
    from twin.control.reference import reachable_range

    names = [g.name for g in cfg.lamps.groups]
    lost = ", ".join(f"{n} {'failed' if k == 0 else f'at {k:.0%}'}"
                     for n, k in zip(names, np.asarray(lamp_gains, float), strict=True) if k < 1.0)
    try:
        top = reachable_range(model, cfg)[1]
    except Exception as exc:  # no steady state at full power: say so, keep the plan
        return f"with {lost}: the reachable fillet mean is unknown ({exc})"
    if T_end > top:
        return f"with {lost} the groups left hold at most {top:.0f} K (fillet mean): the reference's {T_end:.0f} K " \
               "is out of reach"
    return f"with {lost} the groups left hold up to {top:.0f} K: the reference ({T_end:.0f} K) stays reachable"


class FaultRideThrough:
    """The closed loop's part of the fault handling, a collaborator of ``twin.runs.loop.ClosedLoop``.

    It switches the ``detector``'s innovation tests (:meth:`watch`), reports its decisions as events through
    ``note`` and asks ``changes`` (:class:`twin.runs.live_changes.LiveChanges`) for a plan without a lamp group it
    found weak or failed (:meth:`on_detections`), and injects faults into the ``furnace`` (:meth:`injectable`).
    """

    def __init__(self, furnace: Furnace, detector: Any, changes: LampReplanner, note: Callable[[str], None]) -> None:
        self.furnace = furnace
        self.detector = detector  # twin.estimation.fault_detection.FaultDetector
        self._changes = changes
        self._note = note

    def watch(self, t: float, t_end: float) -> None:
        """The detector's innovation tests at run time ``t`` while the estimator's model explains its innovations:
        once a reference whose transition ends at ``t_end`` held still (:func:`innovation_tests_wanted`)."""
        on = innovation_tests_wanted(t, t_end)
        if on != self.detector.innovation_tests:
            self._note(detection_mode_event(on))
        self.detector.set_innovation_tests(on)

    def on_detections(self, t: float, detections: Sequence[Any]) -> None:
        """Report the detector's decisions; a lamp group's new state re-plans the feedforward without it."""
        for d in detections:
            self._note(f"fault detected: {d.text}")
        lamps = [d for d in detections if d.target not in ("TC1", "TC2", "TC3", "TC4")]
        if lamps:
            what = ", ".join(f"{d.target} {d.kind}" for d in lamps)
            try:
                self._changes.lamps_found(self.detector.lamp_gains.copy(), what, t)
            except Exception:  # inline planning failed: the old plan goes on (the loop's event says so)
                log.exception("re-planning for lamp group %s failed", what)

    def injectable(self) -> FaultInjectable:
        """The furnace, to inject faults into; ValueError for one that cannot take them (a real one)."""
        if not isinstance(self.furnace, FaultInjectable):
            raise ValueError(f"faults can be injected only into a simulated furnace, not a {self.furnace.kind} one")
        return self.furnace

    def faults_in_force(self) -> list[FaultSpec]:
        """The faults injected into the furnace (``at`` in run time); none for a real furnace."""
        return self.furnace.faults_in_force() if isinstance(self.furnace, FaultInjectable) else []
