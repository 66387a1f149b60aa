"""A one-page report of a run (PDF or PNG, matplotlib Agg): what was asked, what happened, how well.

Landscape A4: a header with the run's name and scenario; the fillet mean against the reference with
the metric windows shaded; TC reading minus estimate (TC4, the validation TC, bold); the group
powers u (solid) and feedforward u_ff (dotted); the inhomogeneity (T_sup of the paper and the
spread about the fillet mean); the last estimated field with the fillet and the TCs; the metrics in
words with values in K and in % of the setpoint; the run's events (newest last, as many as fit).

Example
-------
>>> import io, json
>>> import numpy as np
>>> n = 50
>>> t = np.linspace(0.0, 4.9, n)
>>> ts = {"t": t, "T_ref": np.full(n, 900.0), "T_mean_hat": np.full(n, 899.0), "eta": np.zeros(n),
...       "tc": np.full((n, 4), 900.0), "tc_hat": np.full((n, 4), 899.5), "u": np.full((n, 6), 0.5),
...       "u_ff": np.full((n, 6), 0.4), "t_field": t, "field_hat": np.full((n, 3, 4), 899.0),
...       "x": np.array([0.05, 0.15, 0.25, 0.35]), "y": np.array([0.03, 0.1, 0.17]), "L_s": 0.4, "W_s": 0.2,
...       "t_E": 2.0, "setpoint": 900.0, "scenario": json.dumps({"duration": 5.0})}
>>> buf = io.BytesIO()
>>> write_report(ts, {"mean_error_steady_max": 0.001}, buf, fmt="png", title="demo")
>>> buf.getvalue()[:4] == b"\\x89PNG"
True
"""

from __future__ import annotations

import json
import textwrap
from collections.abc import Mapping, Sequence
from typing import IO, Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # no pyplot: the server renders reports in worker threads
from matplotlib.gridspec import GridSpec
from matplotlib.patches import Rectangle
from matplotlib.transforms import Bbox

from twin.events import load_events
from twin.physics.fillet import FILLET_X, FILLET_Y, Fillet
from twin.runs.metrics import METRIC_KEYS, METRIC_WORDS, Windows, late_samples, windows_of

TC_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
GROUP_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
TRANSIENT_COLOUR, STEADY_COLOUR = "#cfe3f7", "#d5f0d5"


def _windows(ax: Axes, w: Windows, t_end: float) -> None:
    """The transient and steady windows as shaded bands (clipped to the run)."""
    for (a, b), colour in ((w.transient, TRANSIENT_COLOUR), (w.steady, STEADY_COLOUR)):
        if a < t_end:
            ax.axvspan(a, min(b, t_end), color=colour, alpha=0.6, lw=0, zorder=0)


def _scenario_lines(ts: Mapping[str, Any], w: Windows) -> list[str]:
    try:
        sc = json.loads(str(ts.get("scenario", "{}")))
    except ValueError:
        sc = {}
    ref = sc.get("reference") or {}
    if "points" in ref:
        pts = ", ".join(f"{p[0]:g} s→{p[1]:g} K" for p in ref["points"][:6])
        ref_text = f"points {pts}{' …' if len(ref['points']) > 6 else ''}"
    else:
        ref_text = f"{ref.get('setpoint', float(ts['setpoint'])):g} K in t_E = {ref.get('t_E', float(ts['t_E'])):g} s"
    osc = sc.get("oscillation") or {}
    osc_text = (f"on, {1000 * osc.get('amplitude', 0):.0f} mm, {osc.get('period', 0):g} s" if osc.get("enabled")
                else "off")
    mm = sc.get("mismatch") or {}
    plant = sc.get("plant") or {}
    if plant.get("kind") == "opcua":  # a furnace over OPC UA: its own clock, noise and deviations; no truth
        lines = [f"reference {ref_text} · duration {sc.get('duration', '?')} s · real time",
                 f"oscillation {osc_text} · TC4 at {sc.get('tc4', '?')} (x/L_s, y/W_s)",
                 f"furnace over OPC UA {plant.get('endpoint', '?')} (no truth) · {late_samples(ts)} late samples"]
    else:
        lines = [f"reference {ref_text} · duration {sc.get('duration', '?')} s · speed {sc.get('speed', '?')}",
                 f"oscillation {osc_text} · TC4 at {sc.get('tc4', '?')} (x/L_s, y/W_s) · "
                 f"TC noise {sc.get('tc_noise', '?')} K · seed {sc.get('seed', '?')}"
                 + (f" · truth {sc['truth']}" if "truth" in sc else ""),
                 "plant mismatch: " + ", ".join(f"{k} {100 * float(v):+.0f} %" for k, v in mm.items()) if mm else ""]
    if w.t0 > 0:
        lines.append(f"windows from the last reference change at t = {w.t0:.1f} s: {w.setpoint:g} K, t_E = {w.t_E:g} s")
    return [x for x in lines if x]


def _metrics_table(ax: Axes, metrics: Mapping[str, Any], w: Windows) -> None:
    ax.axis("off")
    rows = []
    for key in METRIC_KEYS:
        v = metrics.get(key)
        if v is None or not np.isfinite(float(v)):
            continue
        rows.append([METRIC_WORDS[key][0], f"{float(v) * w.setpoint:.1f} K", f"{100 * float(v):.2f} %"])
    if not rows:
        ax.text(0, 1, "no metrics (the run ended before its windows)", va="top", fontsize=8)
        return
    table = ax.table(cellText=rows, colLabels=["metric", "K", "%"], bbox=Bbox.from_bounds(0.0, 0.0, 1.0, 1.0),
                     colLoc="left", cellLoc="left", colWidths=[0.70, 0.13, 0.17])
    table.auto_set_font_size(False)
    table.set_fontsize(6.8)
    ax.set_title(f"metrics (% of {w.setpoint:g} K)", fontsize=9, loc="left")


def report_figure(ts: Mapping[str, Any], metrics: Mapping[str, Any], title: str = "",
                  story: Sequence[str] = ()) -> Figure:
    """The report as a matplotlib figure (landscape A4).  ``story``: header lines above the scenario as started
    (what happened: the reference and oscillation in force at the end, the date, furnace and version)."""
    t = np.asarray(ts["t"], float)
    t_end = float(t[-1]) if t.size else 0.0
    w = windows_of(ts)
    fig = Figure(figsize=(11.69, 8.27))
    grid = report_grid(fig, bool(story), len(report_events(load_events(ts))))
    head = fig.add_subplot(grid[0, :])
    head.axis("off")
    head.text(0, 1.0, title or "furnace-twin run", fontsize=13, weight="bold", va="top")
    if story:
        head.text(0, 0.74, "\n".join(story), fontsize=8.5, va="top", weight="bold")
    started = [("as started: " if story and k == 0 else "") + x for k, x in enumerate(_scenario_lines(ts, w))]
    head.text(0, 0.74 - 0.2 * len(story) if story else 0.62, "\n".join(started), fontsize=8.5, va="top",
              family="monospace")

    ax = fig.add_subplot(grid[1, 0])
    _windows(ax, w, t_end)
    ax.plot(t, ts["T_ref"], "k--", lw=1.2, label="reference T_ref")
    ax.plot(t, ts["T_mean_hat"], color="#d62728", lw=1.4, label="fillet mean (estimate)")
    ax.set(title="Fillet mean vs reference", xlabel="t (s)", ylabel="T (K)")
    ax.legend(fontsize=7, loc="lower right")

    ax = fig.add_subplot(grid[1, 1])
    _windows(ax, w, t_end)
    err = np.asarray(ts["tc"], float) - np.asarray(ts["tc_hat"], float)
    for i in range(err.shape[1] if err.ndim == 2 else 0):
        ax.plot(t, err[:, i], color=TC_COLOURS[i % 4], lw=1.6 if i == 3 else 0.8,
                label="TC4 (validation)" if i == 3 else f"TC{i + 1}")
    ax.set(title="TC reading − estimate", xlabel="t (s)", ylabel="K")
    ax.legend(fontsize=7, ncol=4, loc="upper right")

    ax = fig.add_subplot(grid[1, 2])
    u, u_ff = np.asarray(ts["u"], float), np.asarray(ts["u_ff"], float)
    names = [str(g) for g in ts.get("group_names", [f"group {j + 1}" for j in range(u.shape[1])])]
    for j in range(u.shape[1] if u.ndim == 2 else 0):
        colour = GROUP_COLOURS[j % len(GROUP_COLOURS)]
        ax.plot(t, u[:, j], color=colour, lw=1.1, label=names[j] if j < len(names) else f"group {j + 1}")
        ax.plot(t, u_ff[:, j], color=colour, lw=0.8, ls=":")
    ax.set(title="Group powers u (solid), u_ff (dotted)", xlabel="t (s)", ylabel="u / u_max", ylim=(-0.03, 1.05))
    ax.legend(fontsize=6.5, ncol=3, loc="lower right")

    ax = fig.add_subplot(grid[2, 0])
    if "field_hat" in ts and len(ts["field_hat"]):
        _windows(ax, w, t_end)
        tf = np.asarray(ts["t_field"], float)
        fh = np.asarray(ts["field_hat"], float)
        fillet = Fillet.on_grid(ts["x"], ts["y"], float(ts["L_s"]), float(ts["W_s"]))
        ax.plot(tf, fillet.sup(fh, np.interp(tf, t, ts["T_ref"])), color="#805ad5", lw=1.2,
                label="T_sup = max |T̂ − T_ref| (paper)")
        ax.plot(tf, fillet.spread(fh), color="#2c7a7b", lw=1.0, label="spread = max |T̂ − mean|")
        ax.legend(fontsize=7)
    ax.set(title="Inhomogeneity on the fillet", xlabel="t (s)", ylabel="K")

    ax = fig.add_subplot(grid[2, 1])
    if "field_hat" in ts and len(ts["field_hat"]):
        L, W = float(ts["L_s"]), float(ts["W_s"])
        last = np.asarray(ts["field_hat"][-1], float)
        # the colours span the fillet (the cold edges saturate), so its spread shows (issue 27)
        inside = last[Fillet.on_grid(ts["x"], ts["y"], L, W).mask]
        lo, hi = float(np.floor(np.nanmin(inside))), float(np.ceil(np.nanmax(inside)))
        if hi - lo < 4.0:
            lo, hi = (lo + hi) / 2 - 2.0, (lo + hi) / 2 + 2.0
        im = ax.imshow(last, origin="lower", extent=(0, L, 0, W), cmap="turbo", aspect="equal", vmin=lo, vmax=hi)
        fig.colorbar(im, ax=ax, label="K (fillet's range)", shrink=0.8, extend="both")
        ax.add_patch(Rectangle((FILLET_X[0] * L, FILLET_Y[0] * W), (FILLET_X[1] - FILLET_X[0]) * L,
                               (FILLET_Y[1] - FILLET_Y[0]) * W, fill=False, ls="--", color="white"))
        if "tc_positions" in ts:
            p = np.asarray(ts["tc_positions"], float).reshape(-1, 2)
            ax.scatter(p[:, 0], p[:, 1], c=["white"] * 3 + ["#ff4fc8"], edgecolors="black", s=22)
    ax.set(title=f"Estimated field at t = {t_end:.1f} s", xlabel="x (m), along the length", ylabel="y (m)")

    _metrics_table(fig.add_subplot(grid[2, 2]), metrics, w)
    ax = fig.add_subplot(grid[3, :])
    ax.axis("off")
    _event_columns(fig, ax, load_events(ts))
    return fig


def report_grid(fig: Figure, story: bool, n_events: int) -> GridSpec:
    """The page's rows: header, two rows of charts, the event list; the list's row grows from 6 events on
    (up to the height of a chart row) so that every change and warning is listed whole and readable."""
    events = 0.32 if n_events <= 6 else min(1.0, 0.32 + 0.08 * (n_events - 6))
    return fig.add_gridspec(4, 3, height_ratios=[0.42 if story else 0.3, 1, 1, events], hspace=0.6, wspace=0.3,
                            left=0.06, right=0.98, top=0.95, bottom=0.02)


#: advance width of DejaVu Sans Mono (matplotlib's monospace) per em: how many characters a width holds
MONO_EM = 0.602
#: a PNG's glyph advances are hinted to whole pixels: up to one pixel (0.72 pt at 100 dpi) more per character
RASTER_SLACK_PT = 0.72
#: line height of the event list, in font sizes
EVENT_LEADING = 1.25


def _event_columns(fig: Figure, ax: Axes, events: list[Any]) -> None:
    """The event list in the bottom row: wrapped (never cut) to the width it has, in one column if it fits in
    the height down to the page's edge, else two side by side; the font shrinks from 7 to 4.5 pt before that.
    Two columns used to be cut at 95 characters, wider than half the page at 7 pt: long lines overlapped."""
    shown = report_events(events)
    left_out = len(events) - len(shown)
    more = f" ({left_out} other information events in the run's files)" if left_out else ""
    heading = f"the start, every change and every warning{more}:"
    box = ax.get_position()
    width_pt = box.width * fig.get_figwidth() * 72
    height_pt = box.y1 * fig.get_figheight() * 72 - 4  # down to the page's edge
    if not shown:
        ax.text(0, 1, f"{heading}\nnone recorded", fontsize=7, family="monospace", va="top")
        return
    columns: list[list[str]] = []
    size = 7.0
    for size in (7.0, 6.5, 6.0, 5.5, 5.0, 4.5):
        for n_cols in (1, 2):
            chars = int((width_pt / n_cols - 10) / (MONO_EM * size + RASTER_SLACK_PT))
            blocks = [textwrap.wrap(f"{e.t:7.1f} s  {e.text}", chars, subsequent_indent=" " * 11) for e in shown]
            total = sum(len(b) for b in blocks)
            columns = [[]]
            for b in blocks:  # an event's lines stay together; a column is full at half the lines
                if n_cols == 2 and len(columns) == 1 and columns[0] and len(columns[0]) + len(b) > (total + 1) // 2:
                    columns.append([])
                columns[-1] += b
            if (1 + max(len(c) for c in columns)) * size * EVENT_LEADING <= height_pt:
                break
        else:
            continue
        break
    else:  # too many even at 4.5 pt in two columns: as many lines as fit, and how many are left out
        fit = max(1, int(height_pt / (size * EVENT_LEADING)) - 2)
        cut = sum(max(0, len(c) - fit) for c in columns)
        columns = [c[:fit] for c in columns]
        columns[-1].append(f"... {cut} more lines: every event is in the run's files")
    for k, lines in enumerate(columns):
        ax.text(k / len(columns), 1, (heading if k == 0 else "") + "\n" + "\n".join(lines), fontsize=size,
                family="monospace", va="top", linespacing=EVENT_LEADING)


def report_events(events: list[Any]) -> list[Any]:
    """What the report lists: the run's start and end, every live change and every warning or error (issue 27:
    "the last 6 of 24" dropped the reference change); lamp spells and the loop's information stay in the files.

    >>> from twin.events import RunEvent
    >>> ev = [RunEvent.said(0, "run started: x"), RunEvent.said(1, "re-planned (osc): ok"),
    ...       RunEvent.said(5, "re-planned (reference changed at t = 5.0 s to 1050 K in 30 s): ok"),
    ...       RunEvent.said(9, "x failed")]
    >>> [e.t for e in report_events(ev)]
    [0.0, 5.0, 9.0]
    """
    starts = ("run started", "run finished", "run stopped", "run interrupted", "run failed", "run lost",
              "run ended", "fault injected", "faults cleared")
    changes = ("reference changed at", "oscillation on at", "oscillation off at", "calibration at")
    return [e for e in events if e.level != "info" or e.kind in ("run_started", "run_ended")
            or e.text.startswith(starts) or any(c in e.text for c in changes)]


def write_report(ts: Mapping[str, Any], metrics: Mapping[str, Any], out: IO[bytes], *, fmt: str = "pdf",
                 title: str = "", story: Sequence[str] = ()) -> None:
    """Write the one-page report to ``out`` as ``pdf`` or ``png``."""
    if fmt not in ("pdf", "png"):
        raise ValueError(f"report format must be pdf or png, got {fmt!r}")
    report_figure(ts, metrics, title, story).savefig(out, format=fmt, dpi=110)
