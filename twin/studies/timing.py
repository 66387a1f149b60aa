"""Where a study's wall time goes: the cases themselves, and the overhead around them.

From the records computed in one invocation (each with the worker's ``started``/``finished`` clock and
the case's phases ``setup_s``, ``plan_s``, ``run_s``, ``metrics_s``):

- ``case_s``: the closed-loop run of a case (building the loop with its feedforward OCP, the samples, the
  metrics), median;
- ``gap_s``: on each worker, the time between the end of one case and the start of the next (the
  scheduler's hand-off, moving arguments and results), median and mean;
- ``setup_s``: configuration and radiation tables inside a case, median over the cases that found them
  cached, and ``load_s``, the median over the first case of each worker (which loads them);
- ``overhead_fraction``: (mean gap + mean cached set-up) / mean case_s, the per-case overhead;
- ``efficiency``: over the cases of this invocation, sum of the workers' busy time / (wall time x workers),
  which also counts cluster start-up and the idle tail when fewer cases than workers remain.

The per-case figures come from every record of the study, so a resumed study still reports them.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from typing import Any

import numpy as np


def timing_figures(
    records: Sequence[dict[str, Any]], wall_s: float, workers: int, fresh: Sequence[dict[str, Any]] = ()
) -> dict[str, Any]:
    """The figures above over ``records`` (every case of the study, also those of earlier invocations);
    ``efficiency`` over ``fresh``, the cases computed in this invocation of ``wall_s`` on ``workers``.
    None where there is nothing to measure."""
    clocked = [r for r in records if r.get("started") is not None and r.get("finished") is not None]
    timed = [r for r in clocked if r.get("plan_s") is not None and r.get("run_s") is not None]
    out: dict[str, Any] = {"cases": len(clocked), "computed": len(fresh), "wall_s": wall_s, "workers": workers,
                           "case_s": None,
                           "gap_s": None, "gap_s_mean": None, "setup_s": None, "load_s": None,
                           "overhead_fraction": None, "efficiency": None}
    if not timed:
        return out
    case_s = np.array([r["plan_s"] + (r.get("run_s") or 0.0) + (r.get("metrics_s") or 0.0) for r in timed])
    by_worker: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in clocked:  # failed cases occupy their worker too
        by_worker[str(r.get("worker"))].append(r)
    gaps = []
    for rs in by_worker.values():
        rs.sort(key=lambda r: r["started"])
        gaps += [max(0.0, b["started"] - a["finished"]) for a, b in zip(rs, rs[1:], strict=False)]
    cached = [r["setup_s"] for r in clocked if not r.get("radiation_loaded") and r.get("setup_s") is not None]
    loads = [r["setup_s"] for r in clocked if r.get("radiation_loaded") and r.get("setup_s") is not None]
    busy = sum(r["finished"] - r["started"] for r in fresh
               if r.get("started") is not None and r.get("finished") is not None)
    out.update(case_s=float(np.median(case_s)), setup_s=float(np.median(cached)) if cached else None,
               load_s=float(np.median(loads)) if loads else None)
    if gaps:
        out.update(gap_s=float(np.median(gaps)), gap_s_mean=float(np.mean(gaps)))
        overhead = float(np.mean(gaps)) + (float(np.mean(cached)) if cached else 0.0)
        out["overhead_fraction"] = overhead / float(np.mean(case_s))
    if fresh and wall_s > 0 and workers > 0:
        out["efficiency"] = busy / (wall_s * workers)
    return out
