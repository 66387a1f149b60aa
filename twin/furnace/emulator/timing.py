"""What the emulator measures of a hardware-in-the-loop run: its sample period, the client's, the latency
from a TC reading to the lamp write that answers it, and which write each sample of the furnace was
computed with.

Per tick the emulator notes when it took the TC readings (monotonic s); per new watchdog value, when the
write arrived.  A write answers the newest tick before it, so the latency is ``write - reading``; a tick
that no write followed before the next tick is *unanswered* (the client was late or silent for it),
counted between the client's first and last write.  Per sample the furnace advanced, ``applied`` keeps the
watchdog value of the write whose setpoints it held (-1: lamps off by the interlock, or before any write):
a client that answers every sample in time is seen there as 1, 2, 3, ... (its write for sample k carries
k + 1), and every sample computed with an older write, or with the lamps off, shows where the furnace did
not run the loop the client computed.

Example
-------
>>> rec = TimingRecord()
>>> for k in range(4):
...     rec.reading(1.0 + 0.1 * k)
...     if k != 2:
...         rec.write(1.0 + 0.1 * k + 0.004)
>>> s = rec.summary()
>>> s["tc_to_lamp_ms"]["p50"], s["unanswered_readings"], s["readings"]
(4.0, 1, 4)
"""

from __future__ import annotations

import bisect
from collections import deque
from typing import Any

import numpy as np

MAX_EVENTS = 200_000  # about 5.5 h of 0.1 s samples


def percentiles_ms(values_s: Any) -> dict[str, float | int | None]:
    v = np.asarray(values_s, float) * 1000.0
    if v.size == 0:
        return {"n": 0, "p50": None, "p99": None, "max": None}
    return {"n": int(v.size), "p50": round(float(np.percentile(v, 50)), 3),
            "p99": round(float(np.percentile(v, 99)), 3), "max": round(float(v.max()), 3)}


class TimingRecord:
    """Reading and write times of one emulator run (bounded memory)."""

    def __init__(self) -> None:
        self.readings: deque[float] = deque(maxlen=MAX_EVENTS)
        self.writes: deque[float] = deque(maxlen=MAX_EVENTS)
        self.applied: deque[int] = deque(maxlen=MAX_EVENTS)

    def reading(self, t: float) -> None:
        self.readings.append(t)

    def write(self, t: float) -> None:
        self.writes.append(t)

    def step(self, watchdog: int | None) -> None:
        """The furnace advanced one sample with the setpoints of the write carrying ``watchdog`` (``None``: off)."""
        self.applied.append(-1 if watchdog is None else int(watchdog))

    def summary(self) -> dict[str, Any]:
        """Periods and latencies as p50 / p99 / max in ms."""
        r, w = np.asarray(self.readings, float), np.asarray(self.writes, float)
        latency, answered = [], set()
        for t in w:
            k = bisect.bisect_right(r, t) - 1
            if k >= 0 and k not in answered:
                answered.add(k)
                latency.append(t - r[k])
        # ticks while a client was writing: from the one its first write answered to the one its last did
        first = bisect.bisect_right(r, w[0]) - 1 if w.size else 0
        last = bisect.bisect_right(r, w[-1]) - 1 if w.size else -1
        unanswered = sum(1 for k in range(max(first, 0), last + 1) if k not in answered)
        return {
            "readings": int(len(r)), "writes": int(len(w)),
            "twin_periods_s": [round(float(x), 6) for x in np.diff(w)],  # raw, for other statistics
            "emulator_period_ms": percentiles_ms(np.diff(r)),
            "twin_period_ms": percentiles_ms(np.diff(w)),
            "tc_to_lamp_ms": percentiles_ms(latency),
            "unanswered_readings": int(unanswered),
            "applied": [int(a) for a in self.applied],
        }
