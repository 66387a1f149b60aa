"""Readings of a real-time furnace grouped into the twin's samples by their source timestamps.

The furnace's clock drives the samples.  Each reading of a channel (TC1..TC4, Eta) arrives with the
furnace's source timestamp.  :meth:`SampleBuffer.anchor` makes the newest reading (of any channel, so a
dead TC does not stop a run) run time 0 (the start of a run); from then on a reading belongs to sample

    k = round((source time - origin) / t_s),

so sample j collects the readings taken within half a period of t_j = j t_s on the furnace's clock.
:meth:`SampleBuffer.take` waits for sample j until every channel has a reading or the sample is late:
its deadline is when sample j is due on this machine's clock plus ``late_s``, where "due" is learnt from
the arrivals themselves (the smallest recent arrival delay, so neither clock offset nor slow drift
between the two machines matters).  A channel without a reading by then is missing for that sample
(the estimator then predicts without it); a reading that arrives later is counted and dropped.  A sample
that was complete in time but taken only after its deadline (the twin itself fell behind: its commands
for it reach the furnace late) is noted in :attr:`SampleBuffer.overdue_s`.

In **lock step** (``lock_step=True``: the furnace computes a sample only after the twin's write, so no
wall-clock deadline applies) :meth:`SampleBuffer.anchor` takes the newest reading however old, and
:meth:`SampleBuffer.take` waits for sample j as long as ``give_up()`` allows; once its first reading has come,
the other channels have ``late_s`` to follow.

Example
-------
>>> buf = SampleBuffer(t_s=0.1, n_channels=2, late_s=0.05)
>>> for k in range(3):           # the furnace publishes at 1000.0, 1000.1, 1000.2 (its clock)
...     buf.add(0, 300.0 + k, True, 1000.0 + 0.1 * k, arrival=5.0 + 0.1 * k)
...     buf.add(1, 0.0, True, 1000.0 + 0.1 * k, arrival=5.0 + 0.1 * k)
>>> buf.anchor(timeout_s=0.0, now=5.2).source_s      # the newest reading is t = 0
1000.2
>>> buf.add(0, 310.0, True, 1000.3, arrival=5.3)     # sample 1: TC only, the other channel never comes
>>> s = buf.take(1, now=lambda: 5.36)                 # due at 5.3, late after 5.35
>>> [r.value if r else None for r in s]
[310.0, None]
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

AnchorFn = Callable[[], float]


@dataclass(frozen=True)
class Reading:
    """One value of one channel: in twin units, good or not, stamped by the furnace (unix s), arrived (monotonic s)."""

    value: float
    good: bool
    source_s: float
    arrival: float


class SampleBuffer:
    """Thread-safe: the OPC UA thread adds readings, the run's thread anchors and takes samples.

    Parameters
    ----------
    t_s : the sample time (s)
    n_channels : channels per sample
    late_s : how long after it is due a sample may still come (s)
    """

    def __init__(self, t_s: float, n_channels: int, late_s: float, *, delay_window: int = 100,
                 lock_step: bool = False) -> None:
        self.t_s, self.n, self.late_s = float(t_s), int(n_channels), float(late_s)
        self.lock_step = bool(lock_step)
        self._cond = threading.Condition()
        self._origin: float | None = None  # source time of t = 0 (unix s)
        self._slots: dict[int, list[Reading | None]] = {}
        self._newest: list[Reading | None] = [None] * self.n
        self._delays: deque[float] = deque(maxlen=delay_window)  # arrival - (source - origin), all channels
        self._taken = -1  # the last sample handed out
        self._relearn = False  # the next reading filed starts the arrival delays anew (see relearn)
        self.last_arrival = -math.inf
        self.dropped_late = 0  # readings that came after their sample was handed out (or far ahead)
        self.overdue_s = 0.0  # how long after its deadline the last sample was taken (0: in time)

    # ---- the OPC UA thread
    def add(self, channel: int, value: float, good: bool, source_s: float, arrival: float) -> None:
        r = Reading(float(value), bool(good), float(source_s), float(arrival))
        with self._cond:
            self.last_arrival = max(self.last_arrival, r.arrival)
            newest = self._newest[channel]
            if newest is None or r.source_s >= newest.source_s:
                self._newest[channel] = r
            if self._origin is not None:
                self._file(channel, r)
            self._cond.notify_all()

    def _file(self, channel: int, r: Reading) -> None:
        assert self._origin is not None
        rel = r.source_s - self._origin
        k = round(rel / self.t_s)
        if self._relearn:
            self._delays.clear()
            self._relearn = False
        self._delays.append(r.arrival - rel)
        if k <= self._taken or k > self._taken + 1000:
            self.dropped_late += 1
            return
        slot = self._slots.setdefault(k, [None] * self.n)
        if slot[channel] is None:  # the first reading in the sample's window counts
            slot[channel] = r

    # ---- the run's thread
    def anchor(self, timeout_s: float, *, now: float | None = None) -> Reading | None:
        """Start the run clock: the newest reading, if it arrived within the last period (else the next one,
        waiting up to ``timeout_s``), becomes t = 0; sample 0 holds the newest reading of every channel taken
        within half a period of it.  ``None`` if no fresh reading came."""
        t_call = time.monotonic() if now is None else now
        with self._cond:
            def newest() -> Reading | None:
                readings = [r for r in self._newest if r is not None]
                return max(readings, key=lambda r: r.source_s) if readings else None

            def fresh() -> bool:
                r = newest()
                return r is not None and (self.lock_step or r.arrival >= t_call - self.t_s)

            if not fresh():
                self._cond.wait_for(fresh, timeout=timeout_s)
            r0 = newest()
            if r0 is None or not fresh():
                return None
            self._origin = r0.source_s
            self._slots.clear()
            self._delays.clear()
            self._delays.append(r0.arrival)
            self._relearn = False
            self._taken = -1
            self.dropped_late = 0
            self._slots[0] = [r if r is not None and abs(r.source_s - r0.source_s) <= 0.5 * self.t_s else None
                              for r in self._newest]
            return r0

    def relearn(self) -> None:
        """The readings come over a new connection: learn when samples are due from them alone.

        The arrival delay includes the wait for the server's next publishing cycle (up to its interval, 100 ms on
        open62541), whose phase against the furnace's sampling is new with every subscription.  A delay learnt
        on the old connection can make every sample of the new one late until it leaves the window (2 s at
        five channels and 10 Hz); the samples keep their pace on the old delays until the first new reading."""
        with self._cond:
            self._relearn = True

    @property
    def origin(self) -> float | None:
        return self._origin

    def due(self, j: int) -> float:
        """When sample j is due on this machine's monotonic clock (smallest recent arrival delay + t_j)."""
        with self._cond:
            return (min(self._delays) if self._delays else -math.inf) + j * self.t_s

    def take(self, j: int, *, now: AnchorFn = time.monotonic,
             give_up: Callable[[], bool] = lambda: False) -> list[Reading | None]:
        """Sample j's reading per channel (``None`` = missing), waiting until it is complete or late.

        ``give_up()`` is polled while waiting (e.g. the link is lost for good)."""
        if self._origin is None:
            raise RuntimeError("the run clock has not started: anchor() first")
        deadline = math.inf if self.lock_step else self.due(j) + self.late_s
        with self._cond:
            while True:
                slot = self._slots.get(j)
                if slot is not None and all(r is not None for r in slot):
                    break
                if self.lock_step and slot is not None:  # the sample came: its other channels come with it
                    deadline = min(r.arrival for r in slot if r is not None) + self.late_s
                remaining = deadline - now()
                if remaining <= 0 or give_up():
                    break
                self._cond.wait(timeout=min(remaining, 0.05))
            self.overdue_s = max(now() - deadline, 0.0) if slot is not None and None not in slot else 0.0
            slot = self._slots.pop(j, None) or [None] * self.n
            self._taken = max(self._taken, j)
            for k in [k for k in self._slots if k <= j]:
                del self._slots[k]
            return list(slot)

    def newest(self, channel: int) -> Reading | None:
        with self._cond:
            return self._newest[channel]
