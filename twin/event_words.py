"""The words of a run's events: the one place where a :class:`twin.events.RunEvent` becomes a sentence (the
dashboard, the recording, the report and the CLI all show :attr:`twin.events.RunEvent.text`).

Kinds: ``run_started`` (reference, oscillation, duration, speed: as described), ``feasibility`` (a warning of
the start's check), ``saturation`` (one spell of lamp groups at a bound that mattered,
:mod:`twin.control.saturation`), ``run_ended`` (status, error) and ``said`` (a sentence of the loop's own, or of
an older record; a few jargon phrases are put plainly).

>>> from twin.events import RunEvent
>>> words(RunEvent(12.0, "saturation", "warn", {"groups": ["T1h", "T2v"], "bound": "full", "since": 3.0,
...                                              "until": 12.0, "worst_K": 8.24}))
'T1h, T2v at full power from t = 3.0 s for 9.0 s: the fillet mean fell up to 8.2 K behind the reference'
>>> words(RunEvent(30.0, "saturation", "warn", {"groups": ["T3h"], "bound": "off", "since": 20.0, "until": 30.0,
...                                             "worst_K": 4.0}))
'T3h off from t = 20.0 s for 10.0 s: the fillet mean stayed up to 4.0 K above the reference (the lamps cannot cool it)'
>>> words(RunEvent.said(5.0, "the model cannot explain the TCs sample by sample (NIS 14.2)"))
'the thermocouples disagree with the model more than their noise explains (NIS 14.2)'
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol


class Event(Protocol):
    """What the words need of an event (:class:`twin.events.RunEvent` has it; this module does not import
    it, so the words stay below the events in the layers)."""

    @property
    def t(self) -> float: ...

    @property
    def kind(self) -> str: ...

    @property
    def data(self) -> dict[str, Any]: ...

#: what a run's end is called
END_WORDS = {"finished": "run finished", "stopped": "run stopped", "interrupted": "run interrupted",
             "error": "run failed", "plant_lost": "run lost its furnace", "degraded": "run ended blind"}

#: jargon of the loop's own sentences, put plainly
PLAIN = {
    "the model cannot explain the TCs sample by sample":
        "the thermocouples disagree with the model more than their noise explains",
    "solved to a looser tolerance": "planned less precisely than usual (the solver stopped early)",
}


def _started(t: float, d: dict[str, Any]) -> str:
    return (f"run started: reference {d.get('reference')}, oscillation {d.get('oscillation')}, "
            f"{d.get('duration'):g} s, {d.get('speed')}")


def _saturation(t: float, d: dict[str, Any]) -> str:
    who = ", ".join(d.get("groups", []))
    since, until = float(d.get("since", 0.0)), float(d.get("until", t))
    full = d.get("bound") == "full"
    head = f"{who} {'at full power' if full else 'off'} from t = {since:.1f} s for {until - since:.1f} s"
    worst = d.get("worst_K")
    if worst is None:
        return head + (": no headroom left to heat" if full else ": no headroom left to cool")
    if full:
        return f"{head}: the fillet mean fell up to {worst:.1f} K behind the reference"
    return f"{head}: the fillet mean stayed up to {worst:.1f} K above the reference (the lamps cannot cool it)"


def _ended(t: float, d: dict[str, Any]) -> str:
    status = str(d.get("status"))
    words = END_WORDS.get(status, f"run {status}")
    at = f" at t = {t:.1f} s" if status != "finished" else ""
    error = d.get("error")
    return f"{words}{at}{f': {error}' if error else ''}"


def _said(t: float, d: dict[str, Any]) -> str:
    text = str(d.get("text", ""))
    for jargon, plain in PLAIN.items():
        text = text.replace(jargon, plain)
    return text


WORDS: dict[str, Callable[[float, dict[str, Any]], str]] = {
    "run_started": _started,
    "feasibility": lambda t, d: f"feasibility: {d.get('note')}",
    "saturation": _saturation,
    "run_ended": _ended,
    "said": _said,
}


def words(event: Event) -> str:
    """The sentence of ``event`` (an unknown kind: its kind and data, so nothing is lost)."""
    say = WORDS.get(event.kind)
    return say(event.t, event.data) if say is not None else f"{event.kind}: {event.data}"
