"""Headless closed-loop runs: ``furnace-twin run`` (product.md).

A run writes ``metrics.json``, ``timeseries.npz``, PNG figures (not with ``--no-figures``) and, when a sink
factory is given by the composition root (``furnace_twin/cli.py`` passes the rerun
recorder from ``backend``), ``recording.rrd``.  ``twin`` itself never imports
rerun.  The time series is flushed every ``flush_every_s`` simulated seconds and
on stop or error, so a crash loses at most those seconds.  The figures are drawn after the data is written,
by a child process started with the command (:mod:`twin.experiments.figures_process`: matplotlib's import
overlaps the run); the command returns when they are there.

A scenario whose ``plant`` is a furnace over OPC UA runs against it in real time (the furnace's clock
paces the loop), with the link settings of ``FURNACE_TWIN_OPCUA_*`` and certificates under
``$FURNACE_TWIN_DATA_DIR/opcua`` (default ``furnace-data/opcua``).  A furnace lost during the run ends it
with its data written and exit status 3; a run still blind at its end (no thermocouple reading in the
estimate, :mod:`twin.runs.outage`) ends ``degraded`` with exit status 4.  ``metrics.json`` says how every run
ended (``status``, ``status_reason``).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from twin.config import FurnaceConfig
from twin.experiments.figures_process import FigureProcess
from twin.jsonable import jsonable
from twin.limits import furnace_name, scenario_limits
from twin.runs.folder import RunFolder
from twin.runs.guards import EstimateDiverged
from twin.runs.loop import ClosedLoop
from twin.runs.session import RunSession, SnapshotSink
from twin.user_files import ScenarioError, load_scenario

log = logging.getLogger(__name__)


SinkFactory = Callable[[Path, ClosedLoop], SnapshotSink]


def execute_run(
    loop: ClosedLoop,
    out: Path,
    *,
    sink_factories: Iterable[SinkFactory] = (),
    figures: bool = True,
    figure_process: FigureProcess | None = None,
    flush_every_s: float = 10.0,
) -> dict[str, Any]:
    """Run a loop to the end in ``out`` (``twin.runs.session.RunSession.run``: its data written as it goes) and
    plot its figures; returns the metrics with ``out``, ``status`` and ``status_reason`` (also in
    ``metrics.json``: ``finished``, ``degraded`` when it ended blind, ``plant_lost`` with ``error`` if the furnace
    was lost; the data up to then is written all the same).  A run that fails (the estimate diverged, ...) or is
    interrupted (Ctrl-C) writes its data and ``metrics.json`` with status ``error`` / ``stopped``, then raises.

    The figures are drawn after ``timeseries.npz`` and ``metrics.json`` are written: by ``figure_process`` if
    given (``furnace-twin run``), else here (the campaign's workers, which may not start processes)."""
    folder = RunFolder(out)
    session = RunSession(loop, folder, sinks=[make(out, loop) for make in sink_factories])
    result = session.run(flush_every_s=flush_every_s)
    if figures and session.latest is not None:
        if figure_process is not None:
            figure_process.draw(out)
        else:
            from twin.experiments.figures import plot_run
            from twin.runs.record import load_arrays

            plot_run(load_arrays(folder.timeseries), out)
    return {**result, "out": str(out)}


def run_command(cfg: FurnaceConfig, args: Any, sink_factories: Iterable[SinkFactory] = ()) -> int:
    """``furnace-twin run``: one closed-loop run from a scenario file."""
    try:
        limits = scenario_limits(cfg, furnace_name(cfg, getattr(args, "config", None)))
        scenario = load_scenario(args.scenario, limits, oscillate=args.oscillate, tc4=args.tc4)
    except ScenarioError as exc:
        print(f"furnace-twin run: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    out = Path(args.out)
    log.info("run: %s -> %s", scenario.to_json(), out)
    figures = bool(getattr(args, "figures", True))
    with _figure_process(figures) as figure_process:
        return _run(cfg, args, scenario, out, sink_factories, figures, figure_process)


def _figure_process(figures: bool) -> contextlib.AbstractContextManager[FigureProcess | None]:
    """The run's figure process, started now (:mod:`twin.experiments.figures_process`); none without figures, or
    if it cannot be started (then the figures are drawn in this process, after the data, as before)."""
    if figures:
        try:
            return FigureProcess()
        except OSError as exc:
            log.warning("no figure process (%s): the figures will be drawn in this process", exc)
    return contextlib.nullcontext()


def _run(cfg: FurnaceConfig, args: Any, scenario: Any, out: Path, sink_factories: Iterable[SinkFactory],
         figures: bool, figure_process: FigureProcess | None) -> int:
    from twin.furnace.connect import open_furnace
    from twin.radiation import radiation_model

    # a simulated furnace needs the radiation model; a furnace over OPC UA is connected first, so an
    # endpoint the run cannot use fails at once, before the model is loaded
    radiation = radiation_model(cfg) if scenario.plant.kind == "simulated" else None
    try:
        furnace = open_furnace(cfg, scenario, radiation, data_dir=os.environ.get("FURNACE_TWIN_DATA_DIR",
                                                                                 "furnace-data"))
    except (ValueError, OSError) as exc:
        print(f"furnace-twin run: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    try:
        radiation = radiation if radiation is not None else radiation_model(cfg)
        loop = ClosedLoop(cfg, scenario, radiation, furnace=furnace)
    except BaseException:
        furnace.close()
        raise
    try:
        result = execute_run(loop, out, sink_factories=sink_factories, figures=figures, figure_process=figure_process)
    except EstimateDiverged as exc:  # the loop switched the lamps off; the data up to it is in `out`
        print(f"furnace-twin run: stopped: {exc} (data so far in {out})", file=sys.stderr)  # noqa: T201
        return 1
    if args.json:
        print(json.dumps(jsonable(result)))  # noqa: T201
    else:
        for k, v in result.items():
            log.info("%-36s %s", k, f"{v:.4f}" if isinstance(v, float) else v)
    if result.get("status") == "plant_lost":
        print(f"furnace-twin run: {result['error']}; the data so far is in {out}", file=sys.stderr)  # noqa: T201
        return 3
    if result.get("status") == "degraded":  # it ended blind: not "all was well"
        print(f"furnace-twin run: degraded: {result['status_reason']} (data in {out})", file=sys.stderr)  # noqa: T201
        return 4
    return 0
