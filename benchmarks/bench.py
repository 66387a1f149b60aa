"""``furnace-twin bench``: the performance figures of product.md, measured in one process.

| key | meaning |
|---|---|
| precompute_s | exchange factors for all eta positions, cold cache |
| truth_precompute_s | the same for the simulated furnace's own table (symmetric trace of [truth.radiation]) |
| plant_rtf | simulated s per wall s, full-order plant with oscillation, open loop |
| closed_loop_rtf | the same for plant + EKF + LQG over a whole run (feedforward solved), default estimator |
| step_ms | EKF update + controller per sample, median, default estimator |
| closed_loop_rtf_paper, step_ms_paper | the same with the paper's estimator (averaged, no calibration) |
| closed_loop_speed_ratio | closed_loop_rtf / closed_loop_rtf_paper (target >= 0.8) |
| closed_loop_rtf_lqg, step_ms_lqg | the same with the paper's LQG feedback (default estimator) |
| mpc_step_ms_p50, mpc_step_ms_p99 | the MPC's time per sample (condensing + QP), when the feedback is the MPC |
| closed_loop_rtf_mpc_over_lqg | closed_loop_rtf / closed_loop_rtf_lqg (issue 26: at least 0.5) |
| run_wall_s | one default (240 s) ``furnace-twin run``, tables cached, as a subprocess: wall s, median of 3 |
| ocp_s | feedforward OCP solve for a whole run |
| replan_s | re-plan after a reference change, warm-started |
| stream_clients, stream_fps_min | clients served at once (20) at 20 frames/s; the slowest one's frames/s |
| stream_latency_p95_ms | p95 latency from sample to frame, while 2 runs go at speed max (benchmarks.stream) |
| rss_growth_mb | server memory growth over a 1 h run (simulated) at speed max; long_run_rtf: its speed |
| campaign_wall_s | wall s of `campaign --seeds 2` (12 runs, 4 loops, figures; tables cached), one worker per core |

``bench --hil [--duration S]`` measures hardware-in-the-loop timing instead (:mod:`benchmarks.hil`).

Timing lives here, never in the test suite.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

from twin.config import FurnaceConfig

log = logging.getLogger(__name__)


def closed_loop_figures(cfg: FurnaceConfig, radiation: Any, duration: float = 240.0,
                        repeats: int = 3) -> dict[str, float]:
    """closed_loop_rtf over a whole default run (plan solved beforehand) and step_ms, for the default
    estimator and for the paper's configuration (averaged, no calibration), interleaved and repeated.

    step_ms times the estimator (update + predict) and the controller per sample, the part of a step
    the twin adds to the plant.  Re-plans during the run (a calibration moving past its threshold)
    are solved in the background as the server does (``background=True``); the medians of
    ``repeats`` runs are reported, and ``closed_loop_speed_ratio`` = default / paper.
    """
    from twin.runs.loop import ClosedLoop
    from twin.scenario import PAPER_ESTIMATOR, Scenario

    runs: dict[str, list[tuple[float, float]]] = {"": [], "_paper": [], "_lqg": []}
    mpc_ms: list[float] = []
    for _ in range(repeats):
        for suffix, estimator in (("", None), ("_paper", PAPER_ESTIMATOR), ("_lqg", None)):
            scenario = Scenario(duration=duration) if estimator is None else Scenario(
                duration=duration, estimator=estimator.model_dump())
            if suffix == "_lqg":  # the paper's feedback on the default estimator (issue 26: the MPC's cost)
                scenario = Scenario(duration=duration, control={"feedback": "lqg"})
            loop = ClosedLoop(cfg, scenario, radiation, background=True)  # the OCP is solved here
            t0 = time.perf_counter()
            for _ in loop.run():
                pass
            wall = time.perf_counter() - t0
            loop.close()
            runs[suffix].append((duration / wall, float(np.median(loop.compute_ms))))
            if suffix == "" and hasattr(loop.controller, "step_ms"):
                mpc_ms.extend(loop.controller.step_ms)
    out: dict[str, float] = {}
    for suffix, values in runs.items():
        out[f"closed_loop_rtf{suffix}"] = float(np.median([v[0] for v in values]))
        out[f"step_ms{suffix}"] = float(np.median([v[1] for v in values]))
    out["closed_loop_speed_ratio"] = out["closed_loop_rtf"] / out["closed_loop_rtf_paper"]
    if mpc_ms:  # the default feedback is the MPC: its own time per sample, and the loop's speed against the LQG's
        out["mpc_step_ms_p50"] = float(np.percentile(mpc_ms, 50))
        out["mpc_step_ms_p99"] = float(np.percentile(mpc_ms, 99))
        out["closed_loop_rtf_mpc_over_lqg"] = out["closed_loop_rtf"] / out["closed_loop_rtf_lqg"]
    return out


def plant_rtf(cfg: FurnaceConfig, radiation: Any, duration: float = 240.0) -> float:
    """Simulated seconds per wall second of the open-loop plant with oscillation.

    The paper's run: eta = 3 L_h sin(2 pi t / 18 s) (capped at eta_max), all six groups at
    0.6 u_max, cold start, one ``advance`` per sample t_s.
    """
    from twin.furnace.simulated.plant import Plant
    from twin.limits import scenario_limits
    from twin.physics.motion import eta_function
    from twin.scenario import OscillationSpec

    plant = Plant(cfg, radiation)
    amplitude = scenario_limits(cfg).amplitude.default  # the paper's 3 L_h, capped at eta_max
    eta = eta_function(OscillationSpec(enabled=True, amplitude=amplitude, period=18.0))
    u = np.full(cfg.n_groups, 0.6)
    t_s = cfg.sampling.t_s
    state = plant.start(np.full(plant.n, cfg.specimen.initial_temperature))
    for _ in range(5):  # warm-up (first calls allocate)
        state = plant.advance(state, u, t_s, eta)
    state = plant.start(np.full(plant.n, cfg.specimen.initial_temperature))
    n_steps = int(round(duration / t_s))
    t0 = time.perf_counter()
    for _ in range(n_steps):
        state = plant.advance(state, u, t_s, eta)
    wall = time.perf_counter() - t0
    log.info("plant_rtf: %d steps in %.3f s, final fillet mean %.1f K", n_steps, wall, plant.fillet_mean(state.T))
    return duration / wall


#: What one ``furnace-twin run`` leaves in its folder (product.md): the data, the recording and the figures.
RUN_FILES = ("metrics.json", "timeseries.npz", "recording.rrd", "signals.png", "field.png")


def run_wall_seconds(config: str | None = None, repeats: int = 3, duration: float | None = None) -> float:
    """Median wall time (s) of ``repeats`` ``furnace-twin run`` commands of the furnace ``config`` (the default
    scenario: 240 s; or one of ``duration`` s), each a fresh process as a user starts it: imports, model, plan,
    loop, files, figures.  The tables must be cached (:func:`run_bench` loads both first); a failed run, or one
    that did not write all of :data:`RUN_FILES` (its figures are drawn by a child process it waits for), raises."""
    walls = []
    with tempfile.TemporaryDirectory(prefix="furnace-twin-bench-run-") as d:
        scenario: list[str] = []
        if duration is not None:
            scenario = ["--scenario", os.path.join(d, "scenario.json")]
            with open(scenario[1], "w") as f:
                json.dump({"duration": duration}, f)
        for i in range(repeats):
            cmd = [sys.executable, "-m", "furnace_twin.cli", *(["--config", config] if config else []), "run",
                   *scenario, "--out", os.path.join(d, f"run-{i}"), "--json"]
            t0 = time.perf_counter()
            done = subprocess.run(cmd, capture_output=True, text=True, check=False)
            walls.append(time.perf_counter() - t0)
            if done.returncode != 0:
                raise RuntimeError(f"{' '.join(cmd)} failed ({done.returncode}): {done.stderr[-2000:]}")
            missing = [f for f in RUN_FILES if not os.path.isfile(os.path.join(d, f"run-{i}", f))]
            if missing:  # a command that left out part of a run is not what a user waits for
                raise RuntimeError(f"{' '.join(cmd)} did not write {', '.join(missing)}")
    log.info("run_wall_s: %s", ", ".join(f"{w:.2f}" for w in walls))
    return float(np.median(walls))


def campaign_wall_s(cfg: FurnaceConfig, *, seeds: int = 2, workers: int | None = None, t_E: float = 120.0) -> float:
    """Wall seconds of ``furnace-twin campaign --seeds 2`` without the rerun recordings (the runs' files and
    figures, the campaign's tables and figure; tables cached): on a LocalCluster of ``workers`` processes (default
    one per core), ``workers=0`` one run after another in this process (the campaign before issue 21)."""
    import tempfile
    from pathlib import Path

    from twin.experiments.campaign import run_campaign

    with tempfile.TemporaryDirectory(prefix="furnace-twin-bench-campaign-") as out:
        t0 = time.perf_counter()
        run_campaign(cfg, Path(out), t_E, seeds=seeds, workers=workers)
        wall = time.perf_counter() - t0
    log.info("campaign_wall_s: %.1f s (%s seeds, workers %s)", wall, seeds, "in process" if workers == 0 else
             workers or "one per core")
    return wall


def run_bench(cfg: FurnaceConfig, *, include_stream: bool = True, config: str | None = None) -> dict[str, float]:
    from twin.control.feedforward import ocp_seconds
    from twin.control.replan import replan_seconds
    from twin.furnace.simulated.truth import truth_radiation_config
    from twin.radiation import radiation_model
    from twin.radiation.cache import precompute_seconds

    out: dict[str, float] = {}
    log.info("bench: precompute (cold cache)")
    out["precompute_s"] = precompute_seconds(cfg)
    log.info("bench: the truth's precompute (cold cache)")
    out["truth_precompute_s"] = precompute_seconds(truth_radiation_config(cfg), symmetric=True)
    rad = radiation_model(cfg)
    log.info("bench: plant")
    out["plant_rtf"] = plant_rtf(cfg, rad)
    log.info("bench: OCP and re-planning")
    out["ocp_s"] = ocp_seconds(cfg, rad)
    out["replan_s"] = replan_seconds(cfg, rad)
    log.info("bench: closed loop")
    out.update(closed_loop_figures(cfg, rad))
    log.info("bench: furnace-twin run, wall time")
    from twin.furnace.simulated.truth import truth_radiation

    truth_radiation(cfg)  # the simulated furnace's table, cached (the run's other table is rad's)
    out["run_wall_s"] = run_wall_seconds(config)
    log.info("bench: campaign, wall time")
    out["campaign_wall_s"] = campaign_wall_s(cfg)
    if include_stream:
        from benchmarks.stream import stream_bench

        log.info("bench: dashboard stream")
        out.update(stream_bench(cfg))
    return out


def bench_command(cfg: FurnaceConfig, args: Any) -> int:
    figures: dict[str, Any]
    if getattr(args, "hil", False):  # timing of a closed loop over OPC UA (benchmarks.hil)
        from benchmarks.hil import hil_figures

        figures = hil_figures(cfg, getattr(args, "config", None), args.duration)
    else:
        figures = run_bench(cfg, config=getattr(args, "config", None))
    if args.json:
        print(json.dumps(figures))  # noqa: T201
    else:
        for k, v in figures.items():
            sys.stdout.write(f"{k:32s} {v:10.3f}\n" if isinstance(v, float | int) else f"{k:32s} {v}\n")
    return 0
