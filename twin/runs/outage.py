"""When the twin runs blind: no thermocouple reading reaches its estimate, and how a run that did ends.

A furnace over OPC UA can be out for seconds while the run goes on -- its server restarts, the link drops, its
controller stalls -- and a simulated one can lose all its TCs to injected faults.  The estimator then predicts on
the model alone (eq. 14 without eq. 13) and the controller acts on that.  :class:`BlindWatch` follows, per
sample, whether any of TC1..3 reached the estimate (the estimator's ``UpdateInfo.used``):

* blind for :data:`BLIND_S`: the run is *degraded* (:attr:`BlindWatch.blind_since`, the run's status while it
  lasts) and an event says since when and why (no readings came, the TCs report faults, the fault detection
  left them out, they all disagree with the estimate);
* a reading used again: an event says when, after how long;
* the end (:func:`run_ending`): a run that was still blind when it ended is ``degraded``, not ``finished``,
  and every ending carries a reason (``status_reason`` of ``metrics.json`` and ``GET /api/runs/{id}``).

What brings the readings back after an outage lives with those who decide: the fault detection does not take
a common-mode loss of every TC for three dropouts (:mod:`twin.estimation.fault_detection`), and the EKF uses
readings that all disagree with its estimate with its covariance widened (:func:`twin.estimation.ekf.ekf_update`).

Example
-------
>>> w = BlindWatch(t_s=0.1)
>>> events = [e for j in range(40) for e in w.note(0.1 * j, used=not 10 <= j < 30, why="no readings came")]
>>> print(events[0])  # doctest: +ELLIPSIS
blind since t = 1.0 s: no thermocouple reading reached the estimate for 1 s (no readings came); the estimate ...
>>> events[1]
'thermocouple readings used again at t = 3.0 s after 2.0 s blind'
>>> run_ending("finished", None, w, t_end=3.9)
('finished', 'blind once, 2.0 s in all: 1.0-3.0 s (no readings came)')
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: no reading reached the estimate for this long: the run is degraded (a few late samples are not)
BLIND_S = 1.0
N_ESTIMATOR_TCS = 3

#: a run's ends (product.md "Added in turn 3"): what the run record, metrics.json and the API say
ENDINGS = ("finished", "degraded", "stopped", "plant_lost", "error", "interrupted")


@dataclass
class Outage:
    """A spell without readings in the estimate: from ``start`` (s of run time) to ``end`` (``None``: still)."""

    start: float
    end: float | None
    why: str

    def text(self) -> str:
        return f"{self.start:.1f}-{self.end:.1f} s ({self.why})" if self.end is not None else \
            f"since {self.start:.1f} s ({self.why})"


class BlindWatch:
    """Whether the estimate runs blind, sample by sample (module docstring)."""

    def __init__(self, t_s: float, blind_s: float = BLIND_S) -> None:
        self.t_s = float(t_s)
        self.n_blind = max(1, int(round(blind_s / self.t_s)))
        self._without = 0  # samples in a row without a reading in the estimate
        self._first: tuple[float, str] | None = None  # (t, why) of the first of them
        self.outages: list[Outage] = []

    @property
    def blind_since(self) -> float | None:
        """Run time from which no reading has reached the estimate, once that lasted :data:`BLIND_S`."""
        out = self.outages[-1] if self.outages else None
        return out.start if out is not None and out.end is None else None

    def note(self, t: float, used: bool, why: str = "") -> list[str]:
        """Sample t: did a reading reach the estimate (``why`` not: what kept them out)?  Returns its events."""
        if used:
            self._without, self._first = 0, None
            if self.blind_since is None:
                return []
            out = self.outages[-1]
            out.end = float(t)
            return [f"thermocouple readings used again at t = {t:.1f} s after {t - out.start:.1f} s blind"]
        self._without += 1
        if self._first is None:
            self._first = (float(t), why)
        if self._without != self.n_blind:
            return []
        start, cause = self._first
        self.outages.append(Outage(start, None, cause))
        return [f"blind since t = {start:.1f} s: no thermocouple reading reached the estimate for "
                f"{self.n_blind * self.t_s:g} s ({cause}); the estimate runs on the model alone"]

    def summary(self) -> str | None:
        """The outages of the run in one sentence (``None``: none)."""
        if not self.outages:
            return None
        ended = [o for o in self.outages if o.end is not None]
        total = sum(o.end - o.start for o in ended if o.end is not None)
        n = len(self.outages)
        times = "once" if n == 1 else f"{n} times"
        return f"blind {times}, {total:.1f} s in all: " + ", ".join(o.text() for o in self.outages)


def blind_cause(status: tuple[str, ...], excluded: Any, info: Any) -> str:
    """Why none of TC1..3 reached the estimate this sample (for the events), from the readings' status, the
    fault detection's left-out TCs and the estimator's update.

    >>> blind_cause(("unlinked",) * 4, None, None)
    'no readings came from the furnace: the link to it was down or being made again'
    >>> blind_cause(("missing", "unlinked", "missing", "good"), None, None)
    'no readings came from the furnace'
    """
    st = tuple(status[:N_ESTIMATOR_TCS]) or ("good",) * N_ESTIMATOR_TCS
    if all(s == "unlinked" for s in st):
        return "no readings came from the furnace: the link to it was down or being made again"
    if all(s in ("missing", "unlinked") for s in st):
        return "no readings came from the furnace"
    if all(s != "good" for s in st):
        return "the TCs report no usable value"
    left_out = np.asarray(excluded, bool) if excluded is not None else np.zeros(N_ESTIMATOR_TCS, bool)
    if all(s != "good" or out for s, out in zip(st, left_out, strict=True)):
        return "the fault detection left the TCs that read out"
    if info is not None and "gated" in getattr(info, "reasons", ()):
        return "the readings disagree with the estimate beyond its gate"
    return "no usable reading"


def run_ending(end: str, error: str | None, watch: BlindWatch | None, t_end: float) -> tuple[str, str | None]:
    """``(status, status_reason)`` of a run that ended as ``end`` (finished, stopped, plant_lost, error,
    interrupted) with ``error`` (the message of a failure), having been blind as ``watch`` says.

    A run that finished while blind is ``degraded``; the reason names the outages of any run that had some.

    >>> run_ending("stopped", None, None, 12.34)
    ('stopped', 'stopped at t = 12.3 s')
    >>> run_ending("plant_lost", "the link to the furnace was lost and not restored within 10 s", None, 40.0)
    ('plant_lost', 'the link to the furnace was lost and not restored within 10 s')
    """
    outages = watch.summary() if watch is not None else None
    since = watch.blind_since if watch is not None else None
    if end == "finished" and since is not None:
        reason = f"blind from t = {since:.1f} s to the end ({t_end - since:.1f} s without a thermocouple reading " \
                 f"in the estimate)"
        earlier = watch.outages[:-1] if watch is not None else []
        if earlier:
            reason += "; before: " + ", ".join(o.text() for o in earlier)
        return "degraded", reason
    if end == "finished":
        return "finished", outages
    if end == "stopped":
        reason = f"stopped at t = {t_end:.1f} s"
    else:
        reason = error or f"the run ended {end} at t = {t_end:.1f} s"
    return end, f"{reason}; {outages}" if outages else reason
