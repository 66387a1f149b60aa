"""The viser 3D view: the furnace as it is, following one run live or showing a finished one.

The "Run" dropdown picks what the scene shows: "newest running" (the default) follows the
newest active run; a running run is followed live; a finished (stopped, interrupted, ...) run
shows its last estimated field from its ``timeseries.npz``.  The live controls act on the shown
run only while it runs, and are disabled otherwise (a finished run, or no running run to follow).

The view runs on viser's own thread and port (always 127.0.0.1), behind the gate of
``backend.viser.gate``: loopback Host, its own Origin, and with an API token set only a window that
entered it may act (the others are read-only; every control is checked here, on the server).  A daemon
thread reads the shown run's latest sample at <= ``UPDATE_HZ`` and updates the scene, so it never
slows a run.  Everything about the runs comes from the run manager's public methods; GUI
callbacks hand their work to the server's event loop (``RunManager.call_from_thread``), the same
code paths as the REST endpoints.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import viser
from pydantic import ValidationError

from backend.core.messages import field_path, plain_errors
from backend.runs.manager import RunManager
from backend.storage.repository import ACTIVE_STATUSES, RunRow
from backend.streaming.frames import SnapshotLike
from backend.viser.controls import AUTO, Controls, build_controls
from backend.viser.gate import ClientAccess, guarded_viser_server
from backend.viser.scene import FurnaceScene
from backend.viser.stored import stored_snapshot
from twin.scenario import parse_oscillation, parse_reference, parse_scenario

log = logging.getLogger(__name__)

UPDATE_HZ = 5.0  # scene updates per second (<= ~10 Hz); every plate update is a GLB for the browser
RUN_CHOICES = 30  # newest runs offered in the dropdown
OPTIONS_EVERY_S = 2.0  # refresh of the dropdown's runs


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


def status_text(snap: SnapshotLike, run_id: str, status: str, live: bool | None = None) -> str:
    where = "" if (status in ACTIVE_STATUSES if live is None else live) else " (last sample)"
    return (
        f"**run `{run_id}`** · {status}  \n t = {snap.t:.1f} s{where} · η = {1000 * float(snap.eta):.1f} mm  \n"
        f"T_ref = {snap.T_ref:.1f} K · mean (est.) = {snap.T_mean_hat:.1f} K"
    )


class FurnaceView:
    """The viser server, its scene and panel, and the run they show."""

    def __init__(self, manager: RunManager, *, host: str = "127.0.0.1", port: int = 8080,
                 token: str | None = None, allowed_hosts: tuple[str, ...] = (),
                 allowed_origins: tuple[str, ...] = ()):
        self.manager = manager
        self.access = ClientAccess(token)
        self._allowed_hosts, self._allowed_origins = allowed_hosts, allowed_origins
        self.cfg = manager.cfg
        self.host = host
        self.port = port
        self.server: viser.ViserServer | None = None
        self.scene: FurnaceScene | None = None
        self.gui: Controls | None = None
        self.follow: str | None = None  # run id picked in the dropdown; None = the newest active run
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_seq = -1
        self._shown_id: str | None = None  # the run on the scene
        self._static_key: tuple[str, str] | None = None  # (run id, status) of a finished run on the scene
        self._labels: dict[str, str | None] = {AUTO: None}  # dropdown entry -> run id
        self._options_at = 0.0
        self._live_controls: bool | None = None  # whether the live controls are enabled now

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    # ------------------------------------------------------------------ set-up
    def start(self) -> None:
        self.server = guarded_viser_server(self.host, self.port, allowed_hosts=self._allowed_hosts,
                                           allowed_origins=self._allowed_origins)
        self.port = self.server.get_port()
        self.access.attach(self.server)
        self.scene = FurnaceScene(self.server, self.cfg)
        self.gui = build_controls(self.server.gui, self.manager.limits)
        self._wire(self.gui)
        self._thread = threading.Thread(target=self._run, name="viser-scene", daemon=True)
        self._thread.start()
        log.info("viser 3D view on %s", self.url)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.server is not None:
            self.server.stop()

    def _wire(self, g: Controls) -> None:
        """The panel's callbacks: each one a manager call, the same checks as the REST endpoints."""

        @g.run.on_update
        def _(_: Any) -> None:
            self.follow = self._labels.get(g.run.value)
            self._last_seq, self._static_key = -1, None  # redraw for the new choice

        @g.start.on_click
        def _(event: Any) -> None:
            if not self._may_act(event):
                return
            try:
                speed: str | float = g.speed.value if g.speed.value == "max" else float(g.speed.value)
            except (TypeError, ValueError):
                return g.say(f"**refused:** speed {g.speed.value!r} is not 'max' or a number")
            body = {"reference": {"setpoint": g.setpoint.value, "t_E": g.t_E.value},
                    "duration": g.duration.value, "speed": speed,
                    "oscillation": {"enabled": g.oscillate.value, "amplitude": g.amplitude.value,
                                    "period": g.period.value}}
            # the values come from a browser, which can send anything: the same checks as POST /api/runs
            run_id = self._call(lambda: self.manager.start(parse_scenario(body, self.manager.limits)))
            if run_id is not None:
                g.say(f"started run `{run_id}`")
                self.refresh_runs(force=True)
                self.pick(run_id)

        @g.change_reference.on_click
        def _(event: Any) -> None:
            if not self._may_act(event):
                return
            if (run_id := self._followed()) is None:
                return g.say(self._not_running())
            body = {"setpoint": g.new_setpoint.value, "t_E": g.new_t_E.value}
            g.say("re-planning…")
            r = self._call(lambda: self.manager.change(run_id, "reference",
                                                       parse_reference(body, self.manager.limits)))
            if r is not None:
                g.say(f"reference {body['setpoint']:g} K over {body['t_E']:g} s: {r['status']}")

        @g.toggle_oscillation.on_click
        def _(event: Any) -> None:
            if not self._may_act(event):
                return
            if (run_id := self._followed()) is None:
                return g.say(self._not_running())
            now = self.manager.in_force(run_id).oscillation
            body = {**now, "enabled": not now.get("enabled", False)}
            r = self._call(lambda: self.manager.change(run_id, "oscillation",
                                                       parse_oscillation(body, self.manager.limits)))
            if r is not None:
                g.say(f"oscillation {'on' if body['enabled'] else 'off'}: {r['status']}")

        @g.stop.on_click
        def _(event: Any) -> None:
            if not self._may_act(event):
                return
            if (run_id := self._followed()) is None:
                return g.say(self._not_running())
            try:
                self.manager.stop(run_id)
                g.say(f"stopping `{run_id}`")
            except Exception as exc:
                g.say(f"cannot stop: {exc}")

        @g.show_housing.on_update
        def _(_: Any) -> None:
            assert self.scene is not None
            self.scene.show_housing(g.show_housing.value)

        @g.show_sigma.on_update
        def _(_: Any) -> None:
            self._last_seq, self._static_key = -1, None  # redraw the shown sample in the other colouring

    def _may_act(self, event: Any) -> bool:
        """Whether the client behind a GUI event may start, change or stop runs (``ClientAccess``)."""
        assert self.gui is not None
        if self.access.may_act(int(event.client_id)):
            return True
        self.gui.say("**read-only:** this server has an API token: enter it under **Access** to act")
        return False

    def _call(self, make: Any) -> Any:
        """Build a manager coroutine (``make()``, which may refuse its input) and run it on the server's
        event loop; a refusal goes to the message line and gives ``None``."""
        assert self.gui is not None
        try:
            return self.manager.call_from_thread(make())
        except ValidationError as exc:  # the same plain sentences as the REST API's 422s
            self.gui.say("**refused:** " + "; ".join(f"{field_path(e['loc'])}: {e['msg']}"
                                                     for e in plain_errors(exc.errors())))
        except Exception as exc:
            self.gui.say(f"**refused:** {exc}")
        return None

    def _not_running(self) -> str:
        if self.follow is None:
            return "no running run"
        return f"run `{self.follow}` is not running: pick a running one under **Run**"

    # ------------------------------------------------------------------ which run
    def pick(self, run_id: str | None) -> None:
        """Show ``run_id`` (``None``: the newest running run), as if picked in the dropdown."""
        assert self.gui is not None
        label = next((k for k, v in self._labels.items() if v == run_id), None)
        if label is None:
            self.refresh_runs(force=True)
            label = next((k for k, v in self._labels.items() if v == run_id), AUTO)
        if self.gui.run.value == label:
            self.follow = run_id
            self._last_seq, self._static_key = -1, None
        else:
            self.gui.run.value = label  # calls on_update

    def refresh_runs(self, force: bool = False) -> None:
        """Offer the newest runs in the dropdown (and the picked one, even if older)."""
        assert self.gui is not None
        now = time.monotonic()
        if not force and now - self._options_at < OPTIONS_EVERY_S:
            return
        self._options_at = now
        rows = self.manager.runs(RUN_CHOICES)
        if self.follow is not None and all(r.id != self.follow for r in rows):
            try:
                rows.append(self.manager.run(self.follow))
            except LookupError:
                pass
        labels: dict[str, str | None] = {AUTO: None}
        labels.update((run_label(r), r.id) for r in rows)
        if list(labels) != list(self.gui.run.options):
            self._labels = labels
            self.gui.run.options = tuple(labels)  # keeps the value: labels do not change with the status

    def _followed(self) -> str | None:
        """The run the live controls act on: the picked run while it runs, or (no pick) the newest active."""
        live = self.manager.live_runs()
        if self.follow is not None:
            return self.follow if self.follow in live else None
        return live[0] if live else None

    def target(self) -> str | None:
        """The run the scene shows: the picked one; else the newest active; else the last one shown."""
        if self.follow is not None:
            return self.follow
        return self._followed() or self._shown_id

    # ------------------------------------------------------------------ updates
    def sync_controls(self) -> None:
        """Enable the live controls only while there is a running run for them to act on."""
        assert self.gui is not None
        live = self._followed() is not None
        if live == self._live_controls:
            return
        self._live_controls = live
        g = self.gui
        for handle in (g.new_setpoint, g.new_t_E, g.change_reference, g.toggle_oscillation, g.stop):
            handle.disabled = not live

    def update(self) -> None:
        """One scene update (the view's thread calls it at <= ``UPDATE_HZ``)."""
        assert self.gui is not None
        self.refresh_runs()
        self.sync_controls()
        run_id = self.target()
        if run_id is None:
            return
        status = self.manager.status(run_id)
        if status is not None:  # driven by this server
            sample = self.manager.latest(run_id)
            if sample is not None and (run_id != self._shown_id or sample.seq != self._last_seq):
                self._last_seq, self._static_key = sample.seq, None
                self.show(sample.snapshot, run_id, sample.status, live=True)
            elif sample is None and run_id != self._shown_id:
                self._shown_id = run_id
                self.gui.status.content = f"**run `{run_id}`** · {status} (building the controller…)"
            return
        try:
            status = self.manager.run(run_id).status
        except LookupError:
            status = "unknown"
        if self._static_key == (run_id, status):
            return
        self._static_key, self._last_seq = (run_id, status), -1
        if status in ACTIVE_STATUSES:  # registered but not (or no longer) driven by this server
            self._shown_id = run_id
            self.gui.status.content = f"**run `{run_id}`** · {status}"
            return
        s = self.cfg.specimen
        snap = stored_snapshot(self.manager.files(run_id).timeseries, (s.ny, s.nx))
        if snap is None:
            self._shown_id = run_id
            self.gui.status.content = f"**run `{run_id}`** · {status}  \n no stored samples to show"
            return
        self.show(snap, run_id, status)
        if not snap.has_field:
            self.gui.legend.content = "no estimated field stored: the plate shows the last fillet mean"

    def _run(self) -> None:
        period = 1.0 / UPDATE_HZ
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                self.update()
            except Exception:
                log.exception("viser update failed")
            self._stop.wait(max(period - (time.monotonic() - t0), 0.0))

    def show(self, snap: SnapshotLike, run_id: str, status: str, live: bool | None = None) -> None:
        """Put one snapshot on the scene and its run's status on the panel (``live``: a going run's sample)."""
        assert self.scene is not None and self.gui is not None
        sigma = bool(self.gui.show_sigma.value) and getattr(snap, "field_sigma", None) is not None
        lo, hi = self.scene.show(snap, self.cfg.tc_positions(self._tc4(run_id)), sigma=sigma)
        self._shown_id = run_id
        self.gui.status.content = status_text(snap, run_id, status, live)
        self.gui.legend.content = (f"plate colour: sigma of the estimate {lo:.0f} K (white) … {hi:.0f} K (dark blue)"
                                   if sigma else f"plate colour (turbo): {lo:.0f} K (blue) … {hi:.0f} K (red)")

    def _tc4(self, run_id: str) -> tuple[float, float] | None:
        try:
            tc4 = self.manager.scenario(run_id).get("tc4")
        except LookupError:
            return None
        return (float(tc4[0]), float(tc4[1])) if tc4 else None
