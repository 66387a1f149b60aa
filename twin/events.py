"""A run's events and live changes, and their arrays in the run record (``timeseries.npz``).

* events: ``event_t`` (s), ``event_kind``, ``event_json`` (its data) and ``event_level`` (``info``, ``warn`` or
  ``error``), the run's own reports (re-plans, switches; the server adds its own: start, end, changes,
  saturation), with ``event_text``, their words (:mod:`twin.event_words`) when they were recorded; a record
  without ``event_kind`` (older) is read as ``said`` events of its texts;
* live changes: ``change_t`` (s, the first sample that uses the change), ``change_kind``
  (``reference`` or ``oscillation``) and ``change_json`` (the new reference / oscillation as JSON); the
  metrics' windows start at the last reference change (:func:`twin.runs.metrics.windows_of`).

:class:`twin.runs.record.RunRecord` keeps them with its samples; this module names their keys.

Example
-------
>>> a = change_arrays([RunChange(0.1, "reference", {"setpoint": 900.0, "t_E": 5.0})])
>>> a["change_kind"].tolist(), load_changes(a)[0].body["setpoint"]
(['reference'], 900.0)
>>> ev = load_events(event_arrays([RunEvent.said(2.0, "re-planning failed: no solution")]))
>>> ev[0].kind, ev[0].level, ev[0].text
('said', 'warn', 're-planning failed: no solution')
>>> load_events(event_arrays([RunEvent(3.0, "run_ended", "info", {"status": "stopped"})]))[0].text
'run stopped at t = 3.0 s'
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

EVENT_LEVELS = ("info", "warn", "error")


@dataclass(frozen=True)
class RunEvent:
    """One report of a run at run time ``t`` (s): what happened (``kind``), ``info``, ``warn`` or ``error``, and
    its ``data`` (JSON); :attr:`text` is its words (:mod:`twin.event_words`, the one place they are written).
    ``said`` events carry a sentence of the loop's own (``data["text"]``), and are the events of older records."""

    t: float
    kind: str
    level: str = "info"
    data: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def said(cls, t: float, text: str, level: str | None = None) -> RunEvent:
        """A sentence of the loop (or of an older record), at the level its words tell (:func:`event_level`)."""
        return cls(float(t), "said", level or event_level(text), {"text": text})

    @property
    def text(self) -> str:
        from twin.event_words import words

        return words(self)


@dataclass(frozen=True)
class RunChange:
    """A live change applied during a run: from run time ``t`` (s) on, ``kind`` (``reference`` or
    ``oscillation``) is ``body`` (the reference / oscillation as a JSON object)."""

    t: float
    kind: str
    body: dict[str, Any]


def event_level(text: str) -> str:
    """The level of one of the loop's own reports: ``warn`` for a failure (a re-plan that failed), a late
    sample, a lost link to the furnace or a fault the twin detected, else ``info``.

    >>> event_level("re-planning failed (reference not applied): no solution"), event_level("re-planned (x): ok")
    ('warn', 'info')
    >>> event_level("sample at t = 3.0 s late: no TC1 in time (the EKF predicts without them)")
    'warn'
    >>> event_level("link to the furnace restored after 1.2 s")
    'info'
    >>> event_level("blind since t = 4.0 s: ..."), event_level("thermocouple readings used again after 2.0 s blind")
    ('warn', 'info')

    A fault the twin detected is a warning; a fault injected into the simulated furnace is information:

    >>> event_level("fault detected: TC2 dropout at 4.1 s"), event_level("fault injected: T2h failed at t = 9.0 s")
    ('warn', 'info')
    """
    if text.startswith(("fault injected", "faults cleared")):
        return "info"
    if text.startswith("fault detected"):
        return "warn"
    return "warn" if re.search(r"failed| late:|\blost\b|^blind since|fell behind|lamps off|lamps were off", text) \
        else "info"


def event_arrays(events: Iterable[RunEvent]) -> dict[str, Any]:
    """Events as the ``event_t``, ``event_text``, ``event_level`` arrays of the ``timeseries.npz`` layout."""
    ev = list(events)
    return {"event_t": np.asarray([e.t for e in ev], float),
            "event_kind": np.asarray([e.kind for e in ev], dtype=str),
            "event_json": np.asarray([json.dumps(e.data, sort_keys=True) for e in ev], dtype=str),
            "event_text": np.asarray([e.text for e in ev], dtype=str),
            "event_level": np.asarray([e.level for e in ev], dtype=str)}


def load_events(arrays: Mapping[str, Any]) -> list[RunEvent]:
    """The events of a saved run (an older file without ``event_*`` has none; without levels: ``info``)."""
    if "event_t" not in arrays:
        return []
    ts = np.asarray(arrays["event_t"], float)
    levels = np.asarray(arrays["event_level"]).astype(str) if "event_level" in arrays else ["info"] * len(ts)
    if "event_kind" in arrays:
        kinds, data = np.asarray(arrays["event_kind"]).astype(str), np.asarray(arrays["event_json"]).astype(str)
        return [RunEvent(float(t), str(k), str(lv), json.loads(str(d)))
                for t, k, lv, d in zip(ts, kinds, levels, data, strict=True)]
    texts = np.asarray(arrays["event_text"]).astype(str)
    return [RunEvent.said(float(t), str(x), str(lv)) for t, x, lv in zip(ts, texts, levels, strict=True)]


def change_arrays(changes: Iterable[RunChange]) -> dict[str, Any]:
    """Live changes as the ``change_t``, ``change_kind``, ``change_json`` arrays of ``timeseries.npz``."""
    ch = list(changes)
    return {"change_t": np.asarray([c.t for c in ch], float),
            "change_kind": np.asarray([c.kind for c in ch], dtype=str),
            "change_json": np.asarray([json.dumps(c.body, sort_keys=True) for c in ch], dtype=str)}


def load_changes(arrays: Mapping[str, Any]) -> list[RunChange]:
    """The live changes of a saved run, oldest first (none in an older file)."""
    if "change_t" not in arrays:
        return []
    return [RunChange(float(t), str(k), json.loads(str(b))) for t, k, b in
            zip(np.asarray(arrays["change_t"], float), np.asarray(arrays["change_kind"]).astype(str),
                np.asarray(arrays["change_json"]).astype(str), strict=True)]
