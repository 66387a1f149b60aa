"""The one-page report names a run's furnace: a simulation with its noise, seed and truth; a furnace over
OPC UA with its endpoint and the samples that came late (it has no seed, noise or truth of the twin's)."""

from __future__ import annotations

import json

import numpy as np

from twin.experiments.report import _scenario_lines
from twin.runs.metrics import windows_of


def _series(scenario: dict, tc_status: np.ndarray) -> dict:
    n = len(tc_status)
    return {"t": np.arange(n) * 0.1, "t_E": 2.0, "setpoint": 900.0, "tc_status": tc_status,
            "scenario": json.dumps(scenario)}


def test_a_furnace_over_opcua_is_named_with_its_endpoint_and_late_samples() -> None:
    status = np.zeros((10, 4), np.int8)
    status[3, 0] = 2  # sample 3: TC1 missing (late)
    status[7, :] = 2  # sample 7: nothing came
    status[8, 1] = 1  # sample 8: TC2 bad, not late
    sc = {"plant": {"kind": "opcua", "endpoint": "opc.tcp://127.0.0.1:4840/furnace-twin/"}, "speed": 1.0,
          "seed": 3, "tc_noise": 1.0, "truth": "independent", "mismatch": {"emissivity": 0.1}}
    ts = _series(sc, status)
    text = "\n".join(_scenario_lines(ts, windows_of(ts)))
    assert "furnace over OPC UA opc.tcp://127.0.0.1:4840/furnace-twin/ (no truth) · 2 late samples" in text
    assert "real time" in text
    for absent in ("seed", "TC noise", "truth independent", "mismatch", "speed"):
        assert absent not in text, absent


def test_a_simulated_furnace_is_named_with_its_noise_seed_and_truth() -> None:
    sc = {"speed": "max", "seed": 3, "tc_noise": 1.0, "truth": "shared", "mismatch": {"emissivity": 0.1}}
    ts = _series(sc, np.zeros((10, 4), np.int8))
    text = "\n".join(_scenario_lines(ts, windows_of(ts)))
    assert "TC noise 1.0 K · seed 3 · truth shared" in text and "emissivity +10 %" in text
    assert "OPC UA" not in text and "late" not in text


def _event_texts(n: int, length: int):
    """The report's bottom row (the same grid as report_figure) with ``n`` warnings of ``length`` characters,
    drawn; its text artists and the figure's renderer."""
    from matplotlib.figure import Figure

    from twin.events import RunEvent
    from twin.experiments.report import _event_columns, report_grid

    fig = Figure(figsize=(11.69, 8.27))
    ax = fig.add_subplot(report_grid(fig, True, n)[3, :])
    ax.axis("off")
    words = ("the fillet mean stayed up to 9.0 K above the reference (the lamps cannot cool it) while T3h was off "
             "and the feedback had no headroom left")
    events = [RunEvent(float(10 * k), "said", "warn", {"text": f"warning {k}: " + (words * 3)[:length]})
              for k in range(n)]
    _event_columns(fig, ax, events)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    return fig, [t.get_window_extent(renderer) for t in ax.texts], renderer


def test_the_report_event_columns_never_overlap_and_stay_on_the_page() -> None:
    """Issue 27 item 10: two columns cut at 95 characters were wider than half the page at 7 pt, so long lines
    ran into the second column.  Now every event is wrapped whole, in columns that do not overlap."""
    for n, length in ((4, 150), (12, 150), (16, 150), (30, 60), (40, 220)):  # the last one cut, said so
        fig, boxes, _ = _event_texts(n, length)
        width, height = fig.bbox.width, fig.bbox.height
        for b in boxes:
            assert b.x0 >= 0 and b.x1 <= width and b.y0 >= 0 and b.y1 <= height, (n, length, b)
        for a, b in zip(boxes, boxes[1:], strict=False):
            assert a.x1 <= b.x0 or b.x1 <= a.x0, (n, length, a, b)  # side by side, never over each other
    fig, boxes, _ = _event_texts(4, 150)
    assert len(boxes) == 1  # a few events: one column
    fig, _, _ = _event_texts(16, 150)
    assert "more lines" not in fig.axes[0].texts[-1].get_text()  # every event listed whole
    fig, _, _ = _event_texts(40, 220)
    assert "more lines: every event is in the run's files" in fig.axes[0].texts[-1].get_text()
