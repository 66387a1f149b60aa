"""Lamp groups at their bounds: u = u_max (full power) or u = 0 (off), the box constraint of eq. (18).

A group at a bound has no authority left in that direction: at full power it cannot heat faster,
off it cannot cool faster; the feedback (eq. 25) is clipped there.  :func:`bound_flags` marks each
sample (+1 at full power, -1 off, 0 in between); :class:`SaturationWatch` turns the flags of a
running run into one event per spell that matters, when the spell ends: a spell at full power that
lasted ``MIN_FULL_S``, or off that lasted ``MIN_OFF_S`` (single clipped samples are normal feedback
action; a group that idles near zero touches it all the time), during which the fillet mean was at
least ``MATTERS_K`` on the side the bound cannot help (behind the reference at full power, above it
while off).  Lamps off at the start of a heat-up, with the mean below the reference, do not matter and
stay quiet.  A spell ends once the group stayed away from the bound for ``RELEASE_S``, or at the run's
end (:meth:`SaturationWatch.flush`).  The event's words: :mod:`twin.event_words`.

Example
-------
>>> watch = SaturationWatch(("T1h", "T2v"), t_s=0.5)
>>> for k, u2 in enumerate([0.5, 1.0, 1.0, 1.0, 0.9, 1.0, 1.0, 0.8, 0.8, 0.8, 0.8]):
...     for e in watch.update(0.5 * k, [0.4, u2], error=[0, 2, 6, 9, 9, 7, 4, 2, 1, 0, 0][k]):
...         print(e.t, e.level, e.text)
4.0 warn T2v at full power from t = 0.5 s for 3.0 s: the fillet mean fell up to 9.0 K behind the reference
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


#: a spell matters when the fillet mean was this far (K) on the side its bound cannot help
MATTERS_K = 2.0


@dataclass
class _Episode:
    bound: int
    since: float
    last: float  # the last sample at the bound
    worst: float = float("-inf")  # the largest error (K) on the side the bound cannot help
    known: bool = False  # an error was given


class SaturationWatch:
    """One event per spell of a group at a bound that matters (see the module docstring)."""

    def __init__(self, group_names: Sequence[str], t_s: float, min_full_s: float = MIN_FULL_S,
                 min_off_s: float = MIN_OFF_S, release_s: float = RELEASE_S, matters_k: float = MATTERS_K) -> None:
        self.names = tuple(group_names)
        self.t_s = float(t_s)
        self.min_s = {1: float(min_full_s), -1: float(min_off_s)}
        self.release_s = float(release_s)
        self.matters_k = float(matters_k)
        self._open: dict[int, _Episode] = {}

    def _matters(self, ep: _Episode) -> bool:
        long_enough = ep.last - ep.since >= self.min_s[ep.bound] - 1e-9
        return long_enough and (not ep.known or ep.worst >= self.matters_k)

    def update(self, t: float, u: ArrayLike, error: float | None = None) -> list[RunEvent]:
        """Flags of one sample at run time ``t`` (s), with ``error`` = reference - fillet mean estimate (K) if
        known; returns the events of the spells that ended (groups that ended alike share one event)."""
        eps = 1e-9
        ended: list[tuple[int, _Episode]] = []
        for j, flag in enumerate(bound_flags(u)[: len(self.names)].tolist()):
            ep = self._open.get(j)
            if ep is not None and flag == ep.bound:
                ep.last = t
            elif ep is not None and (flag != 0 or t - ep.last >= self.release_s - eps):  # the spell is over
                del self._open[j]
                ended.append((j, ep))
                ep = None
            if flag and ep is None:
                ep = self._open[j] = _Episode(flag, t, t)
            if ep is not None and flag == ep.bound and error is not None and np.isfinite(error):
                ep.known = True
                ep.worst = max(ep.worst, float(error) * ep.bound)  # behind at full power, above while off
        return self._events(t, ended)

    def flush(self, t: float) -> list[RunEvent]:
        """The run ended at ``t``: the events of the spells still open."""
        ended = sorted(self._open.items())
        self._open.clear()
        return self._events(t, ended)

    def _events(self, t: float, ended: list[tuple[int, _Episode]]) -> list[RunEvent]:
        spells: dict[tuple[int, float, float], list[tuple[str, _Episode]]] = {}
        for j, ep in ended:
            if self._matters(ep):
                key = (ep.bound, round(ep.since, 6), round(ep.last + self.t_s, 6))
                spells.setdefault(key, []).append((self.names[j], ep))
        out = []
        for (bound, since, until), eps in spells.items():
            worst = max(ep.worst for _, ep in eps) if all(ep.known for _, ep in eps) else None
            out.append(RunEvent(t, "saturation", "warn" if bound > 0 or worst is not None else "info",
                                {"groups": [n for n, _ in eps], "bound": "full" if bound > 0 else "off",
                                 "since": since, "until": until, "worst_K": worst}))
        return out
