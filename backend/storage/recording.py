"""The rerun recording of one run (``recording.rrd``), written as the run goes.

One :class:`rerun.RecordingStream` per run, saved to its file before anything is logged
(rerun then flushes to disk as it goes).  Entities, on the timeline ``t`` (simulated s):

- ``field/estimated``, ``field/true``: the estimated and the plant's temperature field
  (N_y x N_x, K) as colour-mapped depth images (Turbo, fixed range), every
  ``image_interval`` simulated seconds; ``field/fillet`` the fillet outline, ``field/tc``
  the TC positions (static, in cell coordinates);
- ``temperature/T_ref``, ``temperature/T_mean_hat``, ``temperature/true_mean`` (K);
- ``tc/reading/TC1..4`` and ``tc/error/TC1..4`` (reading minus estimate, K);
- ``power/u/<group>`` and ``power/u_ff/<group>`` (fractions of u_max);
- ``eta`` (m), ``inhomogeneity/estimated`` and ``inhomogeneity/true`` (K);
- with a calibrating estimator ``calibration/<parameter>`` (relative deviation) and
  ``calibration/<parameter>_sigma``; with a shadow estimator ``tc/error_shadow/TC1..4`` (K).
- the estimate's uncertainty (issue 25), when the run reports it: ``field/sigma`` (standard deviation of the
  estimated field, N_y x N_x, K, Viridis over 0..``SIGMA_RANGE_K``) with the field images, and the scalars
  ``uncertainty/sigma_mean`` (K, of the fillet mean) and ``uncertainty/nis`` (per reading);
- ``events``: the run's events (start, live changes, re-plans, saturated groups, feasibility
  warnings, the end) as text logs (``rr.TextLog``, level INFO / WARN / ERROR) at their run time;
  ``faults/injected`` and ``faults/detected`` the fault events (the faults the simulated furnace started
  or cleared, and what the twin's fault detection decided).

Scalars are buffered and sent as columns (``send_columns``) at each :meth:`flush`; the
default blueprint opens the viewer on fields | temperatures and TCs | powers and eta.

With ``live_url`` (``furnace-twin serve --rerun-connect URL``, or the server's own rerun web viewer)
a second stream with the same recording id sends the same entities live to that viewer or gRPC
proxy; the file is written as without it.  The live stream is never flushed from the run's thread
(rerun's gRPC client sends in the background and would block a flush while the viewer is away);
an endpoint that does not answer when the run starts is skipped with a warning.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from backend.streaming.frames import SnapshotLike
from twin.config import FurnaceConfig
from twin.model.tables import PARAMETERS
from twin.physics.fillet import fillet_box

log = logging.getLogger(__name__)

APP_ID = "furnace-twin"
TIMELINE = "t"
TC_NAMES = ("TC1", "TC2", "TC3", "TC4")
SIGMA_RANGE_K = 20.0  # colour range of field/sigma (K): fixed, so that images of a run compare
_LEVELS = {"info": rr.TextLogLevel.INFO, "warn": rr.TextLogLevel.WARN, "error": rr.TextLogLevel.ERROR}


def blueprint(group_names: tuple[str, ...]) -> rrb.Blueprint:
    """Fields on the left, temperatures and TCs in the middle, powers and eta on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(name="estimated field (K)", origin="field", contents=[
                    "field/estimated", "field/fillet", "field/tc"]),
                rrb.Spatial2DView(name="true field (K)", origin="field", contents=[
                    "field/true", "field/fillet", "field/tc"]),
                rrb.Spatial2DView(name="sigma of the estimate (K)", origin="field", contents=[
                    "field/sigma", "field/fillet", "field/tc"]),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="fillet mean vs reference (K)", origin="temperature"),
                rrb.TimeSeriesView(name="TC readings (K)", origin="tc/reading"),
                rrb.TimeSeriesView(name="TC reading - estimate (K)", origin="tc/error"),
                rrb.TextLogView(name="faults and events", origin="/", contents=["faults/**", "events"]),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="group powers u (fraction of u_max)", origin="power/u"),
                rrb.TimeSeriesView(name="feedforward u_ff (fraction of u_max)", origin="power/u_ff"),
                rrb.TimeSeriesView(name="inhomogeneity (K)", origin="inhomogeneity"),
                rrb.TimeSeriesView(name="eta (m)", origin="eta"),
                rrb.TimeSeriesView(name="uncertainty: sigma of the fillet mean (K), NIS", origin="uncertainty"),
                rrb.TextLogView(name="events", origin="events"),
            ),
            column_shares=[2, 2, 2],
        ),
        collapse_panels=True,
    )


def _float(x: float | None) -> float:
    """A snapshot value that a furnace without truth leaves ``None``, as NaN (a gap in the series)."""
    return float("nan") if x is None else float(x)


class RecordingSink:
    """Collects snapshots of one run and writes them to ``path`` (an ``.rrd`` file)."""

    def __init__(
        self,
        cfg: FurnaceConfig,
        run_id: str,
        path: Path,
        *,
        tc_positions: list[tuple[float, float]],
        image_interval: float = 0.5,
        temperature_range: tuple[float, float] = (300.0, 1300.0),
        live_url: str | None = None,
    ) -> None:
        self.cfg = cfg
        self.path = path
        self.image_interval = image_interval
        self.temperature_range = temperature_range
        self.groups = tuple(g.name for g in cfg.lamps.groups)
        self.rec = rr.RecordingStream(APP_ID, recording_id=run_id)
        self.rec.save(str(path), default_blueprint=blueprint(self.groups))
        self.live: rr.RecordingStream | None = None
        if live_url:
            from backend.streaming.rerun_viewer import reachable

            if reachable(live_url):
                self.live = rr.RecordingStream(APP_ID, recording_id=run_id)
                self.live.connect_grpc(live_url, default_blueprint=blueprint(self.groups))
                log.info("run %s streams live to %s", run_id, live_url)
            else:
                log.warning("run %s: no rerun viewer or proxy answers at %s; the recording goes to the file only",
                            run_id, live_url)
        self._streams = [self.rec] if self.live is None else [self.rec, self.live]
        self._rows: list[dict[str, Any]] = []
        self._next_image_t = -np.inf
        self._closed = False
        self._truth = False  # true series declared (a simulated furnace's first sample has them)
        self._log_static(tc_positions)

    def _cell(self, x: float, y: float) -> tuple[float, float]:
        """Absolute position (m) -> image pixel coordinates (column, row) of the N_y x N_x field."""
        s = self.cfg.specimen
        return (x / s.length * s.nx, y / s.width * s.ny)

    def _log(self, entity: str, value: Any, *, static: bool = False) -> None:
        for rec in self._streams:
            rec.log(entity, value, static=static)

    def _set_time(self, t: float) -> None:
        for rec in self._streams:
            rec.set_time(TIMELINE, duration=t)

    def _log_static(self, tc_positions: list[tuple[float, float]]) -> None:
        x0, x1, y0, y1 = fillet_box(self.cfg.specimen.length, self.cfg.specimen.width)
        corners = [self._cell(x, y) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0))]
        self._log("field/fillet", rr.LineStrips2D([corners], colors=[255, 255, 255], radii=0.08),
                     static=True)
        self._log(
            "field/tc",
            rr.Points2D([self._cell(x, y) for x, y in tc_positions], labels=list(TC_NAMES),
                        colors=[[255, 255, 255]] * 3 + [[255, 80, 200]], radii=0.35),
            static=True,
        )
        palette = [[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
                   [140, 86, 75]]
        for kind in ("u", "u_ff"):
            for j, g in enumerate(self.groups):
                self._log(f"power/{kind}/{g}", rr.SeriesLines(names=[f"{kind} {g}"],
                             colors=[palette[j % len(palette)]]), static=True)
        for i, name in enumerate(TC_NAMES):
            for kind in ("reading", "error"):
                self._log(f"tc/{kind}/{name}", rr.SeriesLines(names=[name],
                             colors=[palette[i]]), static=True)
        for name, color in (("T_ref", [0, 0, 0]), ("T_mean_hat", [214, 39, 40])):
            self._log(f"temperature/{name}", rr.SeriesLines(names=[name], colors=[color]), static=True)
        self._log("eta", rr.SeriesLines(names=["eta"]), static=True)
        self._log("inhomogeneity/estimated", rr.SeriesLines(names=["estimated"]), static=True)

    def _declare_truth(self) -> None:
        """The true series, declared with the first sample that has them (a real furnace never does)."""
        self._truth = True
        self._log("temperature/true_mean", rr.SeriesLines(names=["true_mean"], colors=[[31, 119, 180]]),
                     static=True)
        self._log("inhomogeneity/true", rr.SeriesLines(names=["true"]), static=True)

    def add(self, s: SnapshotLike) -> None:
        """Buffer the scalars of one sample; log the field images every ``image_interval`` s."""
        if self._closed:
            return
        if not self._truth and s.true_mean is not None:
            self._declare_truth()
        self._rows.append({
            "t": float(s.t), "eta": float(s.eta), "T_ref": float(s.T_ref), "T_mean_hat": float(s.T_mean_hat),
            "true_mean": _float(s.true_mean), "inh": float(s.inhomogeneity),
            "inh_true": _float(s.true_inhomogeneity),
            "tc": np.asarray(s.tc, dtype=float), "tc_hat": np.asarray(s.tc_hat, dtype=float),
            "u": np.asarray(s.u, dtype=float), "u_ff": np.asarray(s.u_ff, dtype=float),
            "parameters": None if s.parameters is None else np.asarray(s.parameters, dtype=float),
            "parameter_sigma": None if s.parameter_sigma is None else np.asarray(s.parameter_sigma, dtype=float),
            "shadow_tc_hat": None if s.shadow_tc_hat is None else np.asarray(s.shadow_tc_hat, dtype=float),
            "sigma_mean": getattr(s, "sigma_mean", None), "nis": getattr(s, "nis", None),
        })
        if s.t >= self._next_image_t:
            self._next_image_t = float(s.t) + self.image_interval
            self._set_time(float(s.t))
            for name, field in (("estimated", s.field_hat), ("true", s.field_true)):
                if field is None:  # a furnace without a true field
                    continue
                self._log(f"field/{name}", rr.DepthImage(
                    np.asarray(field, dtype=np.float32), meter=1.0, colormap="Turbo",
                    depth_range=list(self.temperature_range)))
            sigma = getattr(s, "field_sigma", None)
            if sigma is not None:
                self._log("field/sigma", rr.DepthImage(np.asarray(sigma, dtype=np.float32), meter=1.0,
                                                       colormap="Viridis", depth_range=[0.0, SIGMA_RANGE_K]))

    def log_event(self, t: float, text: str, level: str = "info") -> None:
        """One event of the run as a text log at run time ``t`` (s); ``level`` info, warn or error.  A fault
        event goes to ``faults/injected`` or ``faults/detected``."""
        if self._closed:
            return
        entity = "events"
        if text.startswith(("fault injected", "faults cleared")):
            entity = "faults/injected"
        elif text.startswith("fault detected"):
            entity = "faults/detected"
        self._set_time(float(t))
        self._log(entity, rr.TextLog(text, level=_LEVELS.get(level, rr.TextLogLevel.INFO)))

    def flush(self) -> None:
        """Send the buffered scalars as columns and push them to the file."""
        if self._closed or not self._rows:
            return
        rows, self._rows = self._rows, []
        times = rr.TimeColumn(TIMELINE, duration=np.array([r["t"] for r in rows]))

        def send(entity: str, values: np.ndarray) -> None:
            for rec in self._streams:
                rec.send_columns(entity, indexes=[times], columns=rr.Scalars.columns(scalars=values))

        series = [("T_ref", "temperature/T_ref"), ("T_mean_hat", "temperature/T_mean_hat"), ("eta", "eta"),
                  ("inh", "inhomogeneity/estimated")]
        if self._truth:  # a furnace without truth (a real one) gets no true curves
            series += [("true_mean", "temperature/true_mean"), ("inh_true", "inhomogeneity/true")]
        for key, entity in series:
            send(entity, np.array([r[key] for r in rows]))
        tc = np.stack([r["tc"] for r in rows])
        tc_err = tc - np.stack([r["tc_hat"] for r in rows])
        for i, name in enumerate(TC_NAMES):
            send(f"tc/reading/{name}", tc[:, i])
            send(f"tc/error/{name}", tc_err[:, i])
        for kind in ("u", "u_ff"):
            arr = np.stack([r[kind] for r in rows])
            for j, g in enumerate(self.groups):
                send(f"power/{kind}/{g}", arr[:, j])
        if all(r["parameters"] is not None for r in rows):
            values = np.stack([r["parameters"] for r in rows])
            sigma = np.stack([r["parameter_sigma"] for r in rows])
            for j, name in enumerate(PARAMETERS):
                if np.isfinite(values[:, j]).any():
                    send(f"calibration/{name}", values[:, j])
                    send(f"calibration/{name}_sigma", sigma[:, j])
        for key in ("sigma_mean", "nis"):
            if all(r[key] is not None for r in rows):
                send(f"uncertainty/{key}", np.array([r[key] for r in rows], dtype=float))
        if all(r["shadow_tc_hat"] is not None for r in rows):
            shadow_err = tc - np.stack([r["shadow_tc_hat"] for r in rows])
            for i, name in enumerate(TC_NAMES):
                send(f"tc/error_shadow/{name}", shadow_err[:, i])
        self.rec.flush()

    def close(self) -> None:
        if self._closed:
            return
        self.flush()
        self._closed = True
        self.rec.flush()
        self.rec.disconnect()
        live, self.live = self.live, None
        if live is not None:  # may wait for an unreachable viewer: not on the run's thread
            threading.Thread(target=live.disconnect, name="rerun-live-close", daemon=True).start()
