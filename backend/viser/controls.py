"""The 3D view's GUI panel, built in one place from the furnace's scenario limits (``twin.limits``,
the same numbers ``GET /api/furnace`` reports): every input's min, max and default come from there."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import viser

from twin.limits import Range, ScenarioLimits

AUTO = "newest running"  # the run dropdown's first entry: follow the newest active run
SPEEDS = ("1", "2", "5", "10", "50")  # real-time factors offered besides "max" (those within the limit)
LIVE_SETPOINT_K = 1050.0  # first value of the live setpoint input (clamped into the furnace's range)
LIVE_TRANSITION_S = 30.0


def _number(gui: viser.GuiApi, label: str, r: Range, step: float, value: float | None = None) -> Any:
    """A number input over ``r`` (an open lower end starts one step above it)."""
    lo = r.lo + step if r.lo_open else r.lo
    initial = r.default if value is None else value
    return gui.add_number(label, min(max(float(initial), lo), r.hi), min=lo, max=r.hi, step=step)


@dataclass
class Controls:
    """Handles of the panel; :class:`backend.viser.view.FurnaceView` wires their callbacks."""

    run: Any
    status: Any
    legend: Any
    setpoint: Any
    t_E: Any
    duration: Any
    speed: Any
    oscillate: Any
    amplitude: Any
    period: Any
    start: Any
    new_setpoint: Any
    new_t_E: Any
    change_reference: Any
    toggle_oscillation: Any
    stop: Any
    show_housing: Any
    show_sigma: Any
    message: Any

    def say(self, text: str) -> None:
        self.message.content = text


def build_controls(gui: viser.GuiApi, limits: ScenarioLimits) -> Controls:
    """The panel: run choice, status, a new run's scenario, live changes, view options."""
    run = gui.add_dropdown("Run", (AUTO,), initial_value=AUTO,
                           hint="what the scene shows: the newest running run, or any run")
    status = gui.add_markdown("**furnace-twin** · no run yet")
    legend = gui.add_markdown("")
    speeds = ["max", *(s for s in SPEEDS if float(s) <= limits.speed.hi)]
    with gui.add_folder("New run"):
        setpoint = _number(gui, "Setpoint (K)", limits.setpoint, 1.0)
        t_E = _number(gui, "t_E (s)", limits.t_E, 0.5)
        duration = _number(gui, "Duration (s)", limits.duration, 1.0)
        speed = gui.add_dropdown("Speed", speeds, initial_value="max")
        oscillate = gui.add_checkbox("Oscillation", False)
        amplitude = _number(gui, "Amplitude (m)", limits.amplitude, 0.001)
        period = _number(gui, "Period (s)", limits.period, 0.5)
        start = gui.add_button("Start run", color="blue")
    with gui.add_folder("Live changes"):
        new_setpoint = _number(gui, "New setpoint (K)", limits.setpoint, 1.0, LIVE_SETPOINT_K)
        new_t_E = _number(gui, "Transition (s)", limits.t_E, 0.5, LIVE_TRANSITION_S)
        change_reference = gui.add_button("Change reference")
        toggle_oscillation = gui.add_button("Toggle oscillation",
                                            hint="on or off with the run's current amplitude and period")
        stop = gui.add_button("Stop run", color="red")
    with gui.add_folder("View", expand_by_default=False):
        show_housing = gui.add_checkbox("Show housing", False)
        show_sigma = gui.add_checkbox("Colour by sigma", False,
                                      hint="the plate shows the estimate's standard deviation (K) instead of the field")
    message = gui.add_markdown("")
    return Controls(run, status, legend, setpoint, t_E, duration, speed, oscillate, amplitude, period, start,
                    new_setpoint, new_t_E, change_reference, toggle_oscillation, stop, show_housing, show_sigma,
                    message)
