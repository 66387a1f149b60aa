"""Specimen motion eta(t) along x (paper sections 2 and 5.2).

The paper's runs use eta(t) = 3 L_h sin(2 pi t / Pi) with Pi = 0.15 t_E; the amplitude and
period come from :class:`twin.scenario.OscillationSpec`.  A disabled spec holds the
specimen at eta = 0.

Example
-------
>>> from twin.scenario import OscillationSpec
>>> eta = eta_function(OscillationSpec(enabled=True, amplitude=0.048, period=18.0))
>>> round(eta(4.5), 6)
0.048
"""

from __future__ import annotations

import math
from collections.abc import Callable

from twin.scenario import OscillationSpec


def eta_function(spec: OscillationSpec, t0: float = 0.0) -> Callable[[float], float]:
    """eta(t) in m: ``amplitude sin(2 pi (t - t0) / period)`` if enabled, else 0.

    Parameters
    ----------
    spec : amplitude (m) and period (s)
    t0 : s, time at which the motion starts from eta = 0 upwards (for switching mid-run)
    """
    if not spec.enabled or spec.amplitude == 0.0:
        return lambda t: 0.0
    a, omega = float(spec.amplitude), 2.0 * math.pi / float(spec.period)
    return lambda t: a * math.sin(omega * (t - t0))
