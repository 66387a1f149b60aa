"""Fixtures of the backend tests (no package: pytest's rootdir-relative import).

``FakeLoop`` is a small, fast stand-in for ``twin.runs.loop.ClosedLoop`` used only where the test
is about the backend's plumbing (queues, limits, status codes, schemathesis); the lifecycle,
websocket and browser tests run the real closed loop with ``small_config()``.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from backend.runs.factory import LoopFactory
from benchmarks.dashboard import CHROMIUM, CHROMIUM_ARGS  # Debian's chromium, headless flags: shared with the benchmark
from twin.physics.grid import cell_centers
from twin.runs.outage import run_ending
from twin.runs.record import RunHeader, RunRecord, Snapshot  # the real types: the stand-in differs only in physics
from twin.runs.series_store import SeriesStore

REPO = Path(__file__).resolve().parents[2]
os.environ.setdefault("FURNACE_TWIN_CACHE", str(REPO / ".cache" / "test-radiation"))
ARTIFACTS = REPO / "test-artifacts"


@dataclass
class FakeLoop:
    """First-order lag towards a ramp reference: T_mean follows T_ref with time constant 5 s.

    eta(t) = A sin(2 pi t / period) when oscillation is on.  ``step_cost_s`` burns wall time
    per step to imitate a slow loop; ``replan_s`` sleeps inside set_reference/set_oscillation.
    A change is reported in the next snapshot's ``events``, like the real loop's.  Points of a
    reference changed after the sample at t count from the next sample, t + t_s (``ClosedLoop.set_reference``).
    """

    cfg: Any
    scenario: Any
    step_cost_s: float = 0.0
    replan_s: float = 0.0
    t: float = 0.0
    T: float = 300.0
    reference: Any = None
    oscillation: Any = None
    rows: list[Snapshot] = field(default_factory=list)
    ref_t0: float = 0.0
    T_start: float = 300.0
    events: list[str] = field(default_factory=list)
    _series: SeriesStore | None = None

    def __post_init__(self) -> None:
        self.reference = self.scenario.reference
        self.oscillation = self.scenario.oscillation
        sp = self.cfg.specimen
        x, y = cell_centers(self.cfg)
        ref = self.scenario.reference
        self.record = RunRecord(RunHeader(
            x=x, y=y, tc_positions=np.asarray(self.cfg.tc_positions(self.scenario.tc4)), L_s=sp.length, W_s=sp.width,
            t_E=float(ref.t_E), setpoint=float(ref.setpoint), group_names=tuple(g.name for g in self.cfg.lamps.groups),
            scenario=self.scenario.to_json()))

    paced_by_furnace = False  # a simulation: the worker paces it by its speed

    @property
    def done(self) -> bool:
        return self.t >= self.scenario.duration - 1e-9

    def T_ref(self, t: float) -> float:
        r, tr = self.reference, t - self.ref_t0
        if hasattr(r, "points"):
            ts, Ts = [p[0] for p in r.points], [p[1] for p in r.points]
            if ts[0] > 0:
                ts, Ts = [0.0, *ts], [self.T_start, *Ts]
            return float(np.interp(tr, ts, Ts))
        return self.T_start + (r.setpoint - self.T_start) * min(tr / r.t_E, 1.0)

    def step(self) -> Snapshot:
        if self.step_cost_s:
            end = time.perf_counter() + self.step_cost_s
            while time.perf_counter() < end:
                pass
        dt = self.cfg.sampling.t_s
        self.t = round(self.t + dt, 9)
        ref = self.T_ref(self.t)
        self.T += (ref - self.T) * dt / 5.0
        o = self.oscillation
        eta = o.amplitude * math.sin(2 * math.pi * self.t / o.period) if o.enabled else 0.0
        s = self.cfg.specimen
        field_ = np.full((s.ny, s.nx), self.T) + np.linspace(-5, 5, s.nx)[None, :]
        snap = Snapshot(
            j=len(self.rows), t=self.t, eta=eta, T_ref=ref, T_mean_hat=self.T,
            field_hat=field_, field_true=field_ + 1.0,
            tc=np.full(4, self.T + 0.5), tc_hat=np.full(4, self.T), u=np.full(6, 0.5), u_ff=np.full(6, 0.4),
            inhomogeneity=5.0, true_mean=self.T + 1.0, true_inhomogeneity=6.0, events=tuple(self.events),
        )
        self.events.clear()
        self.rows.append(snap)
        self.record.append(snap)
        return snap

    def set_reference(self, ref: Any) -> None:
        time.sleep(self.replan_s)
        check_fake_reference(self.cfg, ref)
        t_next = round(self.t + self.cfg.sampling.t_s, 9)  # like ClosedLoop: from the next sample on
        self.reference, self.ref_t0, self.T_start = ref, t_next, self.T_ref(self.t)
        self.events.append(f"reference changed at t = {t_next:.1f} s")
        self.record.note_change(t_next, "reference", ref.model_dump_json())  # like ClosedLoop: the windows move

    def set_oscillation(self, spec: Any) -> None:
        time.sleep(self.replan_s)
        self.oscillation = spec
        t_next = round(self.t + self.cfg.sampling.t_s, 9)
        self.events.append(f"oscillation {'on' if spec.enabled else 'off'} at t = {t_next:.1f} s")
        self.record.note_change(t_next, "oscillation", spec.model_dump_json())

    def timeseries(self) -> dict[str, Any]:
        return self.record.arrays()

    def metrics(self) -> dict[str, Any]:
        err = [abs(s.T_mean_hat - s.T_ref) for s in self.rows]
        return {"mean_error_transient_max": max(err) if err else float("nan"),
                "mean_error_steady_max": float("nan")}

    # the rest of twin.runs.interface.Loop: as a loop on a furnace that takes no faults and never re-plans
    replanning = False

    @property
    def t_s(self) -> float:
        return float(self.cfg.sampling.t_s)

    def set_faults(self, faults: Any) -> None:
        raise ValueError("faults can be injected only into a simulated furnace")

    def add_event(self, event: Any) -> None:
        self.record.add_event(event)

    def append_series(self, folder: Path) -> None:
        if self._series is None:
            self._series = SeriesStore(Path(folder))
        self._series.append(self.record)

    def ending(self, end: str, error: str | None = None) -> tuple[str, str | None]:
        return run_ending(end, error, None, self.t)

    def close(self) -> None:
        pass


def check_fake_reference(cfg: Any, ref: Any) -> None:
    """The fake furnace holds at most 1250 K (the real loop's ``reachable_range``)."""
    temps = [p[1] for p in ref.points] if hasattr(ref, "points") else [ref.setpoint]
    if max(temps) > 1250.0:
        raise ValueError(f"{max(temps):.1f} K is unreachable in the fake furnace (at most 1250 K)")


class FakeFactory(LoopFactory):
    """Makes FakeLoops; like ``DefaultLoopFactory`` it checks a reference before a run starts."""

    def __init__(self, step_cost_s: float = 0.0, replan_s: float = 0.0) -> None:
        self.step_cost_s, self.replan_s = step_cost_s, replan_s

    def __call__(self, cfg: Any, scenario: Any, *, budget: Any = None) -> FakeLoop:
        return FakeLoop(cfg, scenario, step_cost_s=self.step_cost_s, replan_s=self.replan_s)

    def check_reference(self, cfg: Any, ref: Any) -> None:
        check_fake_reference(cfg, ref)


def fake_factory(step_cost_s: float = 0.0, replan_s: float = 0.0) -> FakeFactory:
    return FakeFactory(step_cost_s, replan_s)


@pytest.fixture(scope="session")
def small_cfg():
    from twin.config import small_config

    return small_config()


@pytest.fixture
def artifacts() -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS


@pytest.fixture
def isolated_home(tmp_path, monkeypatch) -> Path:
    """rerun's CLI writes under ~/.config: point HOME and the XDG dirs at a temp dir."""
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    for var in ("XDG_CONFIG_HOME", "XDG_CACHE_HOME", "XDG_DATA_HOME"):
        monkeypatch.setenv(var, str(home / var.lower()))
    return home



@pytest.fixture(scope="module")
def browser():
    """Debian chromium driven by playwright (no `playwright install`); skipped only if absent, and under CI
    (``CI`` set to true, as CI services do) a missing chromium fails the test instead: the suite must not pass
    with its browser tests silently skipped."""
    if not Path(CHROMIUM).exists():
        message = f"{CHROMIUM} is not installed (apt-get install chromium)"
        if os.environ.get("CI", "").lower() in ("true", "1", "yes"):
            pytest.fail(f"CI: {message}; the browser tests cannot run", pytrace=False)
        pytest.skip(message)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


def open_dashboard(browser: Any, url: str, width: int = 1280, height: int = 800) -> tuple[Any, list[str]]:
    """A new page on the dashboard at ``url``, once its header says the server is ok, and the list its console
    errors and page errors go to."""
    page = browser.new_page(viewport={"width": width, "height": height})
    errors: list[str] = []
    # a refused request (401 / 422) is logged by chromium as a failed resource: expected here
    page.on("console", lambda m: errors.append(m.text)
            if m.type == "error" and "Failed to load resource" not in m.text else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url, timeout=120_000)  # plotly.js is 4.6 MB: slow to load on a loaded machine
    page.wait_for_function("document.getElementById('server-state').textContent.startsWith('server ok')",
                           timeout=120_000)
    return page, errors


def wait_model_ready(c: Any, timeout: float = 300.0) -> None:
    """Until ``GET /api/health`` says the radiation models are ready: a POST before that is queued and checked
    later (test_warm_up.py), so a test of what POST itself refuses waits for them."""
    end = time.monotonic() + timeout
    while (h := c.get("/api/health").json())["radiation"] != "ready":
        assert h["radiation"] != "failed" and time.monotonic() < end, h
        time.sleep(0.05)


def wait_status(c: Any, run_id: str, statuses: set[str], timeout: float = 120.0) -> dict:
    """Poll ``GET /api/runs/{id}`` until the run reaches one of ``statuses`` (generous for loaded CI)."""
    end = time.monotonic() + timeout
    body: dict = {}
    while time.monotonic() < end:
        body = c.get(f"/api/runs/{run_id}").json()
        if body["status"] in statuses:
            return body
        time.sleep(0.05)
    raise AssertionError(f"run {run_id} never reached {statuses}: {body.get('status')} {body.get('error')}")


def stream_frames(c: Any, run_id: str, on_frame=None) -> list[dict]:
    """Every frame of the run's stream until it closes; ``on_frame(frame)`` may act on the run."""
    frames = []
    with c.websocket_connect(f"ws://127.0.0.1/api/runs/{run_id}/stream") as ws:
        while True:
            try:
                f = json.loads(ws.receive_text())
            except Exception:
                break
            frames.append(f)
            if on_frame is not None:
                on_frame(f)
    return frames


#: a valid 1 x 1 PNG (the fake study's figure)
PNG_1X1 = bytes.fromhex("89504e470d0a1a0a0000000d4948445200000001000000010806000000"
                        "1f15c4890000000d49444154789c6360f8cf00000301010018dd8db00000000049454e44ae426082")


class FakeStudyRunner:
    """Stands in for ``twin.studies.engine.run_study`` where a test is about the studies API's plumbing:
    every case is done with ``inhomogeneity_steady = 0.01 (index + 1)``, after ``block_s`` or a stop."""

    def __init__(self, block_s: float = 0.0) -> None:
        self.block_s = block_s
        self.calls: list[Any] = []

    def __call__(self, spec: Any, cfg: Any, out: Path, *, cases: Any, on_progress: Any, stop: Any,
                 **_: Any) -> dict[str, Any]:
        from twin.studies.engine import StudyProgress

        self.calls.append(spec)
        on_progress(StudyProgress(len(cases), 0, 0, 0, 1))
        if self.block_s:
            stop.wait(self.block_s)
        stopped = stop.is_set()
        rows = [{"key": c.key, "index": c.index, "params": c.params, "status": "pending" if stopped else "done",
                 "metrics": None if stopped else {"inhomogeneity_steady": 0.01 * (c.index + 1)}, "error": None}
                for c in cases]
        pending = sum(r["status"] == "pending" for r in rows)
        figure = out / "figures" / "heatmap_inhomogeneity_steady.png"
        figure.parent.mkdir(parents=True, exist_ok=True)
        figure.write_bytes(PNG_1X1)
        summary = {"cases": rows, "computed": len(rows) - pending, "skipped": 0, "failed": 0, "pending": pending,
                   "workers": 1, "wall_s": 0.0, "results": str(out / "results.parquet"), "timing": None,
                   "figures": [str(figure)]}
        (out / "summary.json").write_text(json.dumps(summary))
        return summary
