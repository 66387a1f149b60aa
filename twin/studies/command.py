"""``furnace-twin study FILE.toml [--out DIR] [--workers N | --scheduler ADDRESS] [--json] [--keep-series]``.

Exit status 0 when the study ran to its end (failed cases are results, listed in ``study.md``), 2 for a
bad study file or an unreachable cluster, 130 when interrupted (re-run the same command to resume).
"""

from __future__ import annotations

import json
import logging
import os
import sys
from pathlib import Path
from typing import Any

from twin.config import CONFIG_ENV_VAR, FurnaceConfig
from twin.limits import furnace_name, scenario_limits
from twin.studies.cases import expand, resolve_furnace
from twin.studies.cluster import ClusterError, check_scheduler
from twin.studies.spec import StudyError, load_study

log = logging.getLogger(__name__)


def default_out(study_file: str) -> Path:
    return Path("out") / "studies" / Path(study_file).stem


def study_command(cfg: FurnaceConfig, args: Any) -> int:
    from twin.studies.engine import run_study

    if not getattr(args, "verbose", False):  # the scheduler's and nannies' INFO lines would bury the progress bar
        logging.getLogger("distributed").setLevel(logging.WARNING)

    try:
        spec = load_study(args.file)
        source = getattr(args, "config", None) or os.environ.get(CONFIG_ENV_VAR)
        name, furnace = resolve_furnace(spec, cfg, default_name=furnace_name(cfg, source),
                                        relative_to=Path(args.file).resolve().parent)
        cases = expand(spec, furnace, scenario_limits(furnace, name))
    except StudyError as exc:
        print(f"furnace-twin study: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    out = Path(args.out) if args.out else default_out(args.file)
    try:
        if args.scheduler:  # a wrong address said at once, not after tracing a missing table
            check_scheduler(args.scheduler)
        _ensure_radiation_tables(furnace)
        summary = run_study(spec, furnace, out, furnace_name=name, workers=args.workers, scheduler=args.scheduler,
                            keep_series=args.keep_series, progress_bar=True, cases=cases)
    except ClusterError as exc:
        print(f"furnace-twin study: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    except KeyboardInterrupt:
        print(f"furnace-twin study: interrupted; finished cases are kept in {out}: "  # noqa: T201
              "run the same command again to resume", file=sys.stderr)
        return 130
    if args.json:
        print(json.dumps(summary))  # noqa: T201
    else:
        log.info("study: %d cases (%d computed, %d skipped, %d failed) on %d workers in %.1f s; report %s",
                 len(summary["cases"]), summary["computed"], summary["skipped"], summary["failed"],
                 summary["workers"], summary["wall_s"], out / "study.md")
    return 0


def _ensure_radiation_tables(cfg: FurnaceConfig) -> None:
    """Ray-trace a missing radiation table here, with a progress bar, before the workers start: otherwise the
    first case of every worker would wait on the cache lock in silence.  Workers on other machines use their
    own cache (``FURNACE_TWIN_CACHE``)."""
    from twin.furnace.simulated.truth import truth_radiation, truth_radiation_config
    from twin.radiation.cache import cache_path, load_or_compute

    if not cache_path(cfg).exists():
        log.info("radiation tables of this furnace are not cached yet: computing them once before the study")
        load_or_compute(cfg, progress=True)
    if not cache_path(truth_radiation_config(cfg), symmetric=True).exists():
        log.info("the simulated furnace's own radiation table (its truth) is not cached yet: computing it once")
        truth_radiation(cfg, progress=True)
