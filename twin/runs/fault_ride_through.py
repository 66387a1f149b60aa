"""What the loop does about the faults its detector finds (``twin.runs.loop.ClosedLoop``; docs/faults.md).

- :func:`innovation_tests_wanted`: the detector's innovation tests run while the estimator's model can
  explain its innovations: always with the specimen fixed; with the averaged model (eq. 11) of an
  oscillating specimen only once the reference has held still for :data:`SETTLED_S` (while it heats, that
  model's innovations are coloured enough to pass for faults);
- :func:`faulty_model`: the controller's model with each lamp group scaled by the fraction of its power it
  is believed to deliver (a failed group's column of B is 0: the OCP holds it at 0, the LQG leaves it);
- :func:`reach_note`: what the groups left can hold (fillet mean at full power, the model's steady state)
  against the reference, for the event of the re-plan.

Example
-------
>>> innovation_tests_wanted(oscillating=True, t=130.0, t_end=120.0), innovation_tests_wanted(False, 0.0, 120.0)
(False, True)
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from twin.config import FurnaceConfig

#: with the averaged model of an oscillating specimen the innovation tests wait this long (s) after the
#: reference's transition (docs/faults.md: false decisions at 52-64 s of every oscillating heat-up)
SETTLED_S = 20.0


def innovation_tests_wanted(oscillating: bool, t: float, t_end: float) -> bool:
    """See the module docstring."""
    return not oscillating or t >= t_end + SETTLED_S


def detection_mode_event(on: bool, oscillating: bool) -> str:
    """The event that says when the innovation tests switch."""
    if on:
        return "fault detection: innovation tests on" + (" (reference held still)" if oscillating else "")
    return ("fault detection: while the specimen oscillates and the reference moves, the averaged model cannot "
            "explain the TCs sample by sample: only TCs that drop out or stick are detected")


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
