"""The events of one run, as the dashboard, the time series and the recording show them.

:class:`RunEvents` keeps a run's events in order (the stream numbers them by their index), holds the
events that other threads report until the run's own thread adds them (so their order is the order of
the run record), watches the lamp groups for spells at full power or off
(:class:`twin.control.saturation.SaturationWatch`), and says how a run ended.
"""

from __future__ import annotations

from collections import deque

from twin.control.saturation import SaturationWatch
from twin.event_words import END_WORDS
from twin.events import RunEvent

__all__ = ["END_WORDS", "RunEvents", "end_event"]


def end_event(status: str, t: float, error: str | None = None) -> RunEvent:
    """The event of a run's end at run time ``t``.

    >>> end_event("stopped", 12.34).text, end_event("error", 3.0, "boom").level
    ('run stopped at t = 12.3 s', 'error')
    >>> end_event("plant_lost", 40.3, "the link to the furnace was lost").level
    'error'
    >>> end_event("degraded", 240.0, "blind from t = 197.0 s to the end").level
    'warn'
    """
    level = "error" if status in ("error", "plant_lost") else ("warn" if status in ("interrupted", "degraded")
                                                               else "info")
    return RunEvent(float(t), "run_ended", level, {"status": status, "error": error})


class RunEvents:
    """A run's events: ``items`` (oldest first; appended by the run's thread, read anywhere by length then
    slice), a queue for other threads, and the saturation watch of its lamp groups."""

    def __init__(self, group_names: tuple[str, ...], t_s: float) -> None:
        self.items: list[RunEvent] = []
        self._later: deque[RunEvent] = deque()
        self.saturation = SaturationWatch(group_names, t_s)

    def later(self, event: RunEvent) -> None:
        """An event from another thread, added by :meth:`queued` in the run's thread."""
        self._later.append(event)

    def queued(self) -> list[RunEvent]:
        """The events other threads reported since the last call (to be added now)."""
        out = []
        while self._later:
            out.append(self._later.popleft())
        return out
