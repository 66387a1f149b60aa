"""A run described by what happened (issue 27 item 5): the reference and oscillation in force at its end (or now),
live changes marked with their run time, and an automatic label for a run the user has not named.

A run started at 1100 K / 120 s without oscillation, changed live to 1050 K over 30 s at t = 7.6 s and switched to
oscillate at t = 12 s reads "1050 K / 30 s (changed at 7.6 s) · osc on from 12.0 s (48 mm / 18 s)", not
"1100 K / 120 s, osc off" as it started.  Only applied changes count: a refused or still pending change did not
happen.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from backend.storage.repository import ChangeRow

#: how many change times a description lists before "and N more"
MAX_TIMES = 3


@dataclass(frozen=True)
class RunStory:
    reference: str  #: "1050 K / 30 s (changed at 7.6 s)"
    oscillation: str  #: "on from 12.0 s (48 mm / 18 s)", "off", "on (48 mm / 18 s)"
    auto_label: str  #: "fixed", "osc 48 mm / 18 s", "osc 48 mm / 18 s from 12.0 s"

    @property
    def text(self) -> str:
        """One line: "1050 K / 30 s (changed at 7.6 s) · osc on from 12.0 s (48 mm / 18 s)"."""
        return f"{self.reference} · osc {self.oscillation}"

    def to_json(self) -> dict[str, str]:
        return {"reference": self.reference, "oscillation": self.oscillation, "auto_label": self.auto_label,
                "text": self.text}


def short_reference(ref: dict[str, Any]) -> str:
    """ "1100 K / 120 s" for a transition, "3 pts → 1000 K" for points.

    >>> short_reference({"setpoint": 1100, "t_E": 120}), short_reference({"points": [[0, 300], [60, 900]]})
    ('1100 K / 120 s', '2 pts → 900 K')
    """
    pts = ref.get("points")
    if isinstance(pts, list) and pts:
        return f"{len(pts)} pt{'s' if len(pts) > 1 else ''} → {float(pts[-1][1]):.0f} K"
    if ref.get("setpoint") is None:
        return "–"
    return f"{float(ref['setpoint']):g} K / {float(ref.get('t_E', 0)):g} s"


def _osc_shape(osc: dict[str, Any]) -> str:
    return f"{1000 * float(osc.get('amplitude', 0)):.0f} mm / {float(osc.get('period', 0)):g} s"


def _times(ts: list[float]) -> str:
    shown = ", ".join(f"{t:.1f} s" for t in ts[:MAX_TIMES])
    return shown + (f" and {len(ts) - MAX_TIMES} more" if len(ts) > MAX_TIMES else "")


def describe(scenario: dict[str, Any], changes: Iterable[ChangeRow]) -> RunStory:
    """The run's story from its scenario (as started) and its changes (oldest first).

    >>> ch = [ChangeRow(1, "r", "reference", {"setpoint": 1050, "t_E": 30}, 0.0, "applied", 7.6, None),
    ...       ChangeRow(2, "r", "oscillation", {"enabled": True, "amplitude": 0.048, "period": 18}, 0.0,
    ...                 "applied", 12.0, None),
    ...       ChangeRow(3, "r", "reference", {"setpoint": 900, "t_E": 30}, 0.0, "refused", None, "too hot")]
    >>> sc = {"reference": {"setpoint": 1100, "t_E": 120}, "oscillation": {"enabled": False}}
    >>> s = describe(sc, ch)
    >>> s.text
    '1050 K / 30 s (changed at 7.6 s) · osc on from 12.0 s (48 mm / 18 s)'
    >>> s.auto_label
    'osc 48 mm / 18 s from 12.0 s'
    >>> describe(sc, []).text, describe(sc, []).auto_label
    ('1100 K / 120 s · osc off', 'fixed')
    """
    ref: dict[str, Any] = dict(scenario.get("reference") or {})
    osc: dict[str, Any] = dict(scenario.get("oscillation") or {})
    ref_times: list[float] = []
    osc_times: list[float] = []
    for ch in changes:
        if ch.status != "applied" or ch.applied_t is None:
            continue
        if ch.kind == "reference":
            ref, ref_times = dict(ch.body), [*ref_times, float(ch.applied_t)]
        elif ch.kind == "oscillation":
            if bool(ch.body.get("enabled")) != bool(osc.get("enabled")) or ch.body != osc:
                osc_times.append(float(ch.applied_t))
            osc = dict(ch.body)
    reference = short_reference(ref) + (f" (changed at {_times(ref_times)})" if ref_times else "")
    on = bool(osc.get("enabled"))
    if not osc_times:
        oscillation = f"on ({_osc_shape(osc)})" if on else "off"
    elif on:
        oscillation = f"on from {osc_times[-1]:.1f} s ({_osc_shape(osc)})"
    else:
        oscillation = f"off from {osc_times[-1]:.1f} s"
    if on:
        auto = f"osc {_osc_shape(osc)}" + (f" from {osc_times[-1]:.1f} s" if osc_times else "")
    elif osc_times:
        auto = f"osc until {osc_times[-1]:.1f} s"
    else:
        auto = "fixed"
    return RunStory(reference, oscillation, auto)
