"""The viser 3D view: the furnace as it is, following one run live or showing a finished one.

The specimen plate is coloured per vertex by the estimated field and moves with eta between
the two lamp arrays; each lamp is coloured by its group's power (dark = off, bright yellow =
u_max); the gold reflectors, the holders (moving with the plate), the quartz window and,
optionally, the housing are drawn from ``twin.physics.geometry.display_meshes``.  TC markers show
their readings.  The GUI mirrors the REST controls: start, stop, oscillation, setpoint.

The "Run" dropdown picks what the scene shows: "newest running" (the default) follows the
newest active run; a running run is followed live; a finished (stopped, interrupted, ...) run
shows its last estimated field from its ``timeseries.npz``.  The live controls act on the shown
run only while it runs.

The view runs on viser's own thread and port (always 127.0.0.1: it has no token check); a daemon
thread reads the shown run's latest snapshot at <= ``UPDATE_HZ`` and updates the scene, so it
never slows a run.  GUI callbacks hand their work to the server's event loop
(``asyncio.run_coroutine_threadsafe``), the same code paths as the REST endpoints.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
import viser

from backend.frames import SnapshotLike
from backend.repository import RunRow
from backend.run_manager import RunManager
from twin.config import FurnaceConfig
from twin.physics.geometry import display_meshes, specimen_plate_mesh
from twin.runs.record import StoredSnapshot, last_snapshot, load_arrays
from twin.scenario import OscillationSpec, Scenario, TransitionReference

log = logging.getLogger(__name__)

UPDATE_HZ = 5.0  # scene updates per second (<= ~10 Hz); every plate update is a GLB for the browser
GOLD = (212, 175, 55)
LAMP_OFF = np.array([70, 70, 78], dtype=float)
LAMP_ON = np.array([255, 236, 80], dtype=float)
MIN_SPAN_K = 10.0  # colour range of the plate spans at least this many kelvin
#: shadows cost a lot in software WebGL (headless browsers, remote desktops) and add nothing here
NO_SHADOW: dict[str, Any] = {"cast_shadow": False, "receive_shadow": False}
AUTO = "newest running"  # the run dropdown's first entry: follow the newest active run
RUN_CHOICES = 30  # newest runs offered in the dropdown
OPTIONS_EVERY_S = 2.0  # refresh of the dropdown's runs
LIVE = ("queued", "starting", "running")


def run_label(row: RunRow) -> str:
    """Dropdown entry of a run: id and what it does (stable while the run's status changes)."""
    sc = row.scenario or {}
    ref = sc.get("reference") or {}
    if "points" in ref:
        what = f"{len(ref['points'])} points to {ref['points'][-1][1]:g} K"
    else:
        what = f"{ref.get('setpoint', 1100.0):g} K in {ref.get('t_E', 120.0):g} s"
    osc = " · osc." if (sc.get("oscillation") or {}).get("enabled") else ""
    when = time.strftime("%H:%M", time.localtime(row.created_at))
    return f"{row.id} · {when} · {what}{osc}"


def stored_snapshot(path: Path, shape: tuple[int, int]) -> StoredSnapshot | None:
    """The last sample of a run's stored time series (:func:`twin.runs.record.last_snapshot`); ``None`` if
    the file is missing, empty or unreadable.  Without a stored field of this grid the plate shows the
    last fillet mean."""
    try:
        snap = last_snapshot(load_arrays(path))
    except (OSError, ValueError, KeyError, IndexError) as exc:
        log.warning("cannot read %s for the 3D view: %s", path, exc)
        return None
    if snap is not None and snap.field_hat.shape != tuple(shape):
        log.warning("%s holds a field of %s cells, the furnace has %s", path, snap.field_hat.shape, shape)
        return None
    return snap


def turbo_rgb(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Temperatures (K) -> uint8 RGB with matplotlib's turbo map over [lo, hi]."""
    from matplotlib import colormaps

    x = np.clip((np.asarray(values, dtype=float) - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
    return (colormaps["turbo"](x)[..., :3] * 255).astype(np.uint8)


def colour_range(field: np.ndarray, step: float = 5.0) -> tuple[float, float]:
    """Colour range (K) of the plate: its min..max widened to multiples of ``step`` and to at
    least ``MIN_SPAN_K``, so the colours do not flicker with the noise of the estimate."""
    f = np.asarray(field, dtype=float)
    finite = f[np.isfinite(f)]
    if not finite.size:
        return (290.0, 310.0)
    lo, hi = step * np.floor(finite.min() / step), step * np.ceil(finite.max() / step)
    if hi - lo < MIN_SPAN_K:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - MIN_SPAN_K / 2, mid + MIN_SPAN_K / 2
    return (float(lo), float(hi))


def vertex_values(field: np.ndarray) -> np.ndarray:
    """Cell-centred field (N_y, N_x) -> vertex values ((N_y+1) (N_x+1),) by averaging the
    (up to four) cells around each vertex; vertex (i, j) at index i + (N_x + 1) j."""
    f = np.asarray(field, dtype=float)
    p = np.pad(f, 1, mode="edge")
    v = 0.25 * (p[:-1, :-1] + p[1:, :-1] + p[:-1, 1:] + p[1:, 1:])
    return v.ravel()


def plate_mesh(cfg: FurnaceConfig, colors: np.ndarray) -> trimesh.Trimesh:
    """Both faces of the specimen at eta = 0 with per-vertex colours ((N_x+1)(N_y+1), 3) uint8."""
    verts, faces, _ = specimen_plate_mesh(cfg, 0.0)
    back = verts.copy()
    back[:, 2] = -back[:, 2]
    n = len(verts)
    return trimesh.Trimesh(
        vertices=np.vstack([verts, back]),
        faces=np.vstack([faces, faces[:, ::-1] + n]),
        vertex_colors=np.vstack([colors, colors]),
        process=False,
    )


def lamp_colors(cfg: FurnaceConfig, u: np.ndarray) -> np.ndarray:
    """(N_lamps, 3) uint8: each lamp coloured by the power fraction of its group (0 if none)."""
    frac = np.clip(cfg.group_matrix @ np.nan_to_num(np.asarray(u, dtype=float)), 0.0, 1.0)
    return (LAMP_OFF + frac[:, None] * (LAMP_ON - LAMP_OFF)).astype(np.uint8)


class FurnaceView:
    """The viser server and the scene of the followed run."""

    def __init__(self, cfg: FurnaceConfig, manager: RunManager, *, host: str = "127.0.0.1", port: int = 8080):
        self.cfg = cfg
        self.manager = manager
        self.host = host
        self.port = port
        self.server: viser.ViserServer | None = None
        self.follow: str | None = None  # run id picked in the dropdown; None = the newest active run
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_seq = -1
        self._lamp_rgb: np.ndarray | None = None
        self._plate_rgb: np.ndarray | None = None
        self._shown_id: str | None = None  # the run on the scene
        self._static_key: tuple[str, str] | None = None  # (run id, status) of a finished run on the scene
        self._labels: dict[str, str | None] = {AUTO: None}  # dropdown entry -> run id
        self._options_at = 0.0

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    # ------------------------------------------------------------------ set-up
    def start(self) -> None:
        self.server = viser.ViserServer(host=self.host, port=self.port, label="furnace-twin", verbose=False)
        self.port = self.server.get_port()
        self._build_scene()
        self._build_gui()
        self._thread = threading.Thread(target=self._run, name="viser-scene", daemon=True)
        self._thread.start()
        log.info("viser 3D view on %s", self.url)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.server is not None:
            self.server.stop()

    def _build_scene(self) -> None:
        assert self.server is not None
        sc = self.server.scene
        s = self.cfg.specimen
        sc.set_up_direction("-x")  # x points down along the specimen (default_furnace.toml frame)
        # from the vertical-lamp side: those lamps are sparse, so the plate is seen between them
        self.server.initial_camera.position = (s.length / 2 + 0.05, s.width / 2 + 0.32, -0.55)
        self.server.initial_camera.look_at = (s.length / 2, s.width / 2, 0.0)
        self.server.initial_camera.up = (-1.0, 0.0, 0.0)
        self.lamps: list[Any] = []
        self.holders: list[Any] = []
        self.housing: list[Any] = []
        for name, kind, verts, faces in display_meshes(self.cfg, 0.0):
            if kind == "lamp":
                self.lamps.append(sc.add_mesh_simple(f"/furnace/lamps/{name}", verts, faces, color=tuple(LAMP_OFF),
                                                     **NO_SHADOW))
            elif kind == "reflector":
                sc.add_mesh_simple(f"/furnace/{name}", verts, faces, color=GOLD, opacity=0.18, side="double",
                                   **NO_SHADOW)
            elif kind == "holder":
                self.holders.append(sc.add_mesh_simple(f"/furnace/{name}", verts, faces, color=(110, 120, 135),
                                                       **NO_SHADOW))
            elif kind == "window":
                sc.add_mesh_simple(f"/furnace/{name}", verts, faces, color=(170, 210, 240), opacity=0.15,
                                   side="double", **NO_SHADOW)
            elif kind == "housing":
                self.housing.append(sc.add_mesh_simple(f"/furnace/housing/{name}", verts, faces,
                                                       color=(150, 155, 165), opacity=0.12, side="double",
                                                       visible=False, **NO_SHADOW))
        field = np.full((s.ny, s.nx), s.initial_temperature)
        cold = turbo_rgb(vertex_values(field), 290.0, 310.0)
        self.plate = sc.add_mesh_trimesh("/furnace/specimen", plate_mesh(self.cfg, cold), **NO_SHADOW)
        self.tc_markers = []
        self.tc_labels = []
        for k, (x, y) in enumerate(self.cfg.tc_positions()):
            color = (255, 80, 200) if k == 3 else (255, 255, 255)
            self.tc_markers.append(sc.add_icosphere(f"/furnace/tc/TC{k + 1}", radius=0.004, color=color,
                                                    position=(x, y, 0.0), **NO_SHADOW))  # pokes out of both faces
            self.tc_labels.append(sc.add_label(f"/furnace/tc/TC{k + 1}/label", f"TC{k + 1}",
                                               position=(0.0, 0.0, 0.0),
                                               anchor="bottom-left" if k == 1 else "top-left"))

    def _build_gui(self) -> None:
        assert self.server is not None
        gui = self.server.gui
        self.in_run = gui.add_dropdown("Run", (AUTO,), initial_value=AUTO,
                                       hint="what the scene shows: the newest running run, or any run")
        self.md_status = gui.add_markdown("**furnace-twin** · no run yet")
        self.md_legend = gui.add_markdown("")
        with gui.add_folder("New run"):
            self.in_setpoint = gui.add_number("Setpoint (K)", 1100.0, min=301.0, max=1300.0, step=1.0)
            self.in_tE = gui.add_number("t_E (s)", 120.0, min=1.5, max=3600.0, step=1.0)
            self.in_duration = gui.add_number("Duration (s)", 240.0, min=1.0, max=3600.0, step=1.0)
            self.in_speed = gui.add_dropdown("Speed", ["max", "1", "2", "5", "10", "50"], initial_value="max")
            self.in_osc = gui.add_checkbox("Oscillation", False)
            self.in_amp = gui.add_number("Amplitude (m)", 0.048, min=0.0, max=0.05, step=0.001)
            self.in_period = gui.add_number("Period (s)", 18.0, min=1.0, max=600.0, step=0.5)
            start = gui.add_button("Start run", color="blue")
        with gui.add_folder("Live changes"):
            self.in_new_sp = gui.add_number("New setpoint (K)", 1050.0, min=301.0, max=1300.0, step=1.0)
            self.in_new_tE = gui.add_number("Transition (s)", 30.0, min=1.5, max=3600.0, step=1.0)
            ref_btn = gui.add_button("Change reference")
            osc_btn = gui.add_button("Toggle oscillation")
            stop_btn = gui.add_button("Stop run", color="red")
        with gui.add_folder("View", expand_by_default=False):
            show_housing = gui.add_checkbox("Show housing", False)
        self.md_msg = gui.add_markdown("")

        @self.in_run.on_update
        def _(_: Any) -> None:
            self.follow = self._labels.get(self.in_run.value)
            self._last_seq, self._static_key = -1, None  # redraw for the new choice

        @start.on_click
        def _(_: Any) -> None:
            speed: str | float = self.in_speed.value if self.in_speed.value == "max" else float(self.in_speed.value)
            scenario = Scenario.model_validate({
                "reference": {"setpoint": self.in_setpoint.value, "t_E": self.in_tE.value},
                "duration": self.in_duration.value, "speed": speed,
                "oscillation": {"enabled": self.in_osc.value, "amplitude": self.in_amp.value,
                                "period": self.in_period.value},
            })
            run_id = self._call(self.manager.start(scenario))
            if run_id is not None:
                self._say(f"started run `{run_id}`")
                self.refresh_runs(force=True)
                self.pick(run_id)

        @ref_btn.on_click
        def _(_: Any) -> None:
            if (run_id := self._followed()) is None:
                return self._say(self._not_running())
            ref = TransitionReference(setpoint=self.in_new_sp.value, t_E=self.in_new_tE.value)
            self._say("re-planning…")
            r = self._call(self.manager.change(run_id, "reference", ref))
            if r is not None:
                self._say(f"reference {ref.setpoint:g} K over {ref.t_E:g} s: {r['status']}")

        @osc_btn.on_click
        def _(_: Any) -> None:
            if (run_id := self._followed()) is None:
                return self._say(self._not_running())
            active = self.manager.active.get(run_id)
            enabled = not (active is not None and active.worker.oscillation.enabled)
            spec = OscillationSpec(enabled=enabled, amplitude=self.in_amp.value, period=self.in_period.value)
            r = self._call(self.manager.change(run_id, "oscillation", spec))
            if r is not None:
                self._say(f"oscillation {'on' if enabled else 'off'}: {r['status']}")

        @stop_btn.on_click
        def _(_: Any) -> None:
            if (run_id := self._followed()) is None:
                return self._say(self._not_running())
            try:
                self.manager.stop(run_id)
                self._say(f"stopping `{run_id}`")
            except Exception as exc:
                self._say(f"cannot stop: {exc}")

        @show_housing.on_update
        def _(_: Any) -> None:
            for h in self.housing:
                h.visible = show_housing.value

    def _say(self, text: str) -> None:
        self.md_msg.content = text

    def _not_running(self) -> str:
        if self.follow is None:
            return "no running run"
        return f"run `{self.follow}` is not running: pick a running one under **Run**"

    def pick(self, run_id: str | None) -> None:
        """Show ``run_id`` (``None``: the newest running run), as if picked in the dropdown."""
        label = next((k for k, v in self._labels.items() if v == run_id), None)
        if label is None:
            self.refresh_runs(force=True)
            label = next((k for k, v in self._labels.items() if v == run_id), AUTO)
        if self.in_run.value == label:
            self.follow = run_id
            self._last_seq, self._static_key = -1, None
        else:
            self.in_run.value = label  # type: ignore[misc]  # viser's typed property; calls on_update

    def refresh_runs(self, force: bool = False) -> None:
        """Offer the newest runs in the dropdown (and the picked one, even if older)."""
        now = time.monotonic()
        if not force and now - self._options_at < OPTIONS_EVERY_S:
            return
        self._options_at = now
        rows = self.manager.repo.list_runs(RUN_CHOICES)
        if self.follow is not None and all(r.id != self.follow for r in rows):
            row = self.manager.repo.get(self.follow)
            rows += [row] if row is not None else []
        labels: dict[str, str | None] = {AUTO: None}
        labels.update((run_label(r), r.id) for r in rows)
        if list(labels) != list(self.in_run.options):
            self._labels = labels
            self.in_run.options = tuple(labels)  # keeps the value: labels do not change with the status

    def _call(self, coro: Any) -> Any:
        """Run a manager coroutine on the server's event loop from viser's thread."""
        loop = self.manager.event_loop
        if loop is None:
            coro.close()
            self._say("server not ready")
            return None
        try:
            return asyncio.run_coroutine_threadsafe(coro, loop).result(timeout=self.manager.settings.change_timeout_s)
        except Exception as exc:
            self._say(f"**refused:** {exc}")
            return None

    # ------------------------------------------------------------------ updates
    def _followed(self) -> str | None:
        """The run the live controls act on: the picked run while it runs, or (no pick) the newest active."""
        active = self.manager.active
        if self.follow is not None:
            return self.follow if self.follow in active else None
        if not active:
            return None
        return max(active, key=lambda k: active[k].started_monotonic)

    def target(self) -> str | None:
        """The run the scene shows: the picked one; else the newest active; else the last one shown."""
        if self.follow is not None:
            return self.follow
        return self._followed() or self._shown_id

    def update(self) -> None:
        """One scene update (the view's thread calls it at <= ``UPDATE_HZ``)."""
        self.refresh_runs()
        run_id = self.target()
        if run_id is None:
            return
        run = self.manager.active.get(run_id)
        if run is not None:
            if run.worker.latest is not None and (run_id != self._shown_id or run.worker.seq != self._last_seq):
                self._last_seq, self._static_key = run.worker.seq, None
                self.show(run.worker.latest, run_id, run.status)
            elif run.worker.latest is None and run_id != self._shown_id:
                self._shown_id = run_id
                self.md_status.content = f"**run `{run_id}`** · {run.status} (building the controller…)"
            return
        row = self.manager.repo.get(run_id)
        status = row.status if row is not None else "unknown"
        if self._static_key == (run_id, status):
            return
        self._static_key, self._last_seq = (run_id, status), -1
        if status in LIVE:  # registered but not (or no longer) driven by this server
            self._shown_id = run_id
            self.md_status.content = f"**run `{run_id}`** · {status}"
            return
        s = self.cfg.specimen
        snap = stored_snapshot(self.manager.files(run_id).timeseries, (s.ny, s.nx))
        if snap is None:
            self._shown_id = run_id
            self.md_status.content = f"**run `{run_id}`** · {status}  \n no stored samples to show"
            return
        self.show(snap, run_id, status)
        if not snap.has_field:
            self.md_legend.content = "no estimated field stored: the plate shows the last fillet mean"

    def _run(self) -> None:
        period = 1.0 / UPDATE_HZ
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                self.update()
            except Exception:
                log.exception("viser update failed")
            self._stop.wait(max(period - (time.monotonic() - t0), 0.0))

    def show(self, snap: SnapshotLike, run_id: str, status: str) -> None:
        """Put one snapshot on the scene (plate colours and position, lamps, TCs, text)."""
        assert self.server is not None
        field = np.asarray(snap.field_hat, dtype=float)
        lo, hi = colour_range(field)
        eta = float(snap.eta)
        colours = turbo_rgb(vertex_values(field), lo, hi)
        with self.server.atomic():
            if self._plate_rgb is None or not np.array_equal(colours, self._plate_rgb):
                # a new GLB only when a vertex colour changed (each one costs the browser a parse)
                self.plate = self.server.scene.add_mesh_trimesh(
                    "/furnace/specimen", plate_mesh(self.cfg, colours), position=(eta, 0.0, 0.0), **NO_SHADOW)
                self._plate_rgb = colours
            else:
                self.plate.position = (eta, 0.0, 0.0)
            for h in self.holders:
                h.position = (eta, 0.0, 0.0)
            rgb = lamp_colors(self.cfg, np.asarray(snap.u))
            for k, handle in enumerate(self.lamps):
                if self._lamp_rgb is None or not np.array_equal(rgb[k], self._lamp_rgb[k]):
                    handle.color = tuple(int(c) for c in rgb[k])
            self._lamp_rgb = rgb
            for k, (x, y) in enumerate(self.manager.cfg.tc_positions(self._tc4(run_id))):
                self.tc_markers[k].position = (x + eta, y, 0.0)
                reading = float(np.asarray(snap.tc)[k])
                self.tc_labels[k].text = f"TC{k + 1} {reading:.1f} K" if np.isfinite(reading) else f"TC{k + 1} –"
        self._shown_id = run_id
        self.md_status.content = self._status_text(snap, run_id, status)
        self.md_legend.content = f"plate colour (turbo): {lo:.0f} K (blue) … {hi:.0f} K (red)"

    @staticmethod
    def _status_text(snap: SnapshotLike, run_id: str, status: str) -> str:
        where = "" if status in LIVE else " (last sample)"
        return (
            f"**run `{run_id}`** · {status}  \n t = {snap.t:.1f} s{where} · η = {1000 * float(snap.eta):.1f} mm  \n"
            f"T_ref = {snap.T_ref:.1f} K · mean (est.) = {snap.T_mean_hat:.1f} K"
        )

    def _tc4(self, run_id: str) -> tuple[float, float] | None:
        run = self.manager.active.get(run_id)
        if run is not None:
            return run.worker.scenario.tc4
        row = self.manager.repo.get(run_id)
        tc4 = (row.scenario or {}).get("tc4") if row is not None else None
        return (float(tc4[0]), float(tc4[1])) if tc4 else None
