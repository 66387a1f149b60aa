"""Lamp groups at their bounds: u = u_max (full power) or u = 0 (off), the box constraint of eq. (18).

A group at a bound has no authority left in that direction: at full power it cannot heat faster,
off it cannot cool faster; the feedback (eq. 25) is clipped there.  :func:`bound_flags` marks each
sample (+1 at full power, -1 off, 0 in between); :class:`SaturationWatch` turns the flags of a
running run into events: a spell at full power once it lasted ``MIN_FULL_S``, a spell off once it
lasted ``MIN_OFF_S`` (single clipped samples are normal feedback action and stay quiet; a group that
idles near zero touches it all the time), and the end of a reported spell once the group stayed
away from the bound for ``RELEASE_S`` (a group that leaves for a moment does not start a new spell).

Example
-------
>>> watch = SaturationWatch(("T1h", "T2v"), t_s=0.5)
>>> for k, u2 in enumerate([0.5, 1.0, 1.0, 1.0, 0.9, 1.0, 1.0, 0.8, 0.8, 0.8, 0.8]):
...     for e in watch.update(0.5 * k, [0.4, u2]):
...         print(e.t, e.text)
1.5 T2v at full power (100 %) since t = 0.5 s: no headroom left to heat
4.0 T2v below full power again since t = 3.5 s, after 3.0 s
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.events import RunEvent

AT_BOUND = 1e-3  # a group within this fraction of u_max of 0 or 1 is at its bound
MIN_FULL_S = 1.0  # a spell at full power is reported after this long
MIN_OFF_S = 5.0  # a spell off is reported after this long
RELEASE_S = 1.0  # a spell ends when the group stayed this long away from its bound


def bound_flags(u: ArrayLike) -> NDArray[np.int8]:
    """+1 where a group is at full power, -1 where it is off, 0 in between (same shape as ``u``; NaN: 0).

    >>> bound_flags([1.0, 0.9995, 0.5, 0.0, float("nan")]).tolist()
    [1, 1, 0, -1, 0]
    """
    a = np.asarray(u, float)
    out = np.zeros(a.shape, np.int8)
    with np.errstate(invalid="ignore"):
        out[a >= 1.0 - AT_BOUND] = 1
        out[a <= AT_BOUND] = -1
    return out


@dataclass
class _Episode:
    bound: int
    since: float
    last: float  # the last sample at the bound
    reported: bool = False


class SaturationWatch:
    """Events of the groups that stay at a bound (see the module docstring for the durations)."""

    def __init__(self, group_names: Sequence[str], t_s: float, min_full_s: float = MIN_FULL_S,
                 min_off_s: float = MIN_OFF_S, release_s: float = RELEASE_S) -> None:
        self.names = tuple(group_names)
        self.t_s = float(t_s)
        self.min_s = {1: float(min_full_s), -1: float(min_off_s)}
        self.release_s = float(release_s)
        self._open: dict[int, _Episode] = {}

    def update(self, t: float, u: ArrayLike) -> list[RunEvent]:
        """Flags of one sample at run time ``t`` (s); returns the events it causes: ``warn`` when a group has
        been at full power for ``MIN_FULL_S``, ``info`` when a group has been off for ``MIN_OFF_S`` and when a
        reported spell ends.  Groups that start or end alike in the same sample share one event."""
        eps = 1e-9
        started: dict[tuple[int, float], list[str]] = {}  # (bound, since) -> groups
        ended: dict[tuple[int, float, float], list[str]] = {}  # (bound, left, duration) -> groups
        for j, flag in enumerate(bound_flags(u)[: len(self.names)].tolist()):
            ep = self._open.get(j)
            if ep is not None and flag == ep.bound:
                ep.last = t
            elif ep is not None and (flag != 0 or t - ep.last >= self.release_s - eps):  # the spell is over
                del self._open[j]
                if ep.reported:
                    left = ep.last + self.t_s
                    ended.setdefault((ep.bound, round(left, 6), round(left - ep.since, 6)), []).append(self.names[j])
                ep = None
            if flag and ep is None:
                ep = self._open[j] = _Episode(flag, t, t)
            if ep is not None and not ep.reported and ep.last - ep.since >= self.min_s[ep.bound] - eps:
                ep.reported = True
                started.setdefault((ep.bound, round(ep.since, 6)), []).append(self.names[j])
        events = []
        for (bound, since), names in started.items():
            who = ", ".join(names)
            if bound > 0:
                events.append(RunEvent(t, f"{who} at full power (100 %) since t = {since:.1f} s: no headroom left "
                                          "to heat", "warn"))
            else:
                events.append(RunEvent(t, f"{who} off (0 %) since t = {since:.1f} s: no headroom left to cool",
                                       "info"))
        for (bound, left, duration), names in ended.items():
            what = "below full power" if bound > 0 else "on"
            events.append(RunEvent(t, f"{', '.join(names)} {what} again since t = {left:.1f} s, after "
                                      f"{duration:.1f} s", "info"))
        return events
