"""The budget of a sample: what each part of :meth:`twin.runs.loop.ClosedLoop.step` costs (docs/performance.md).

One default run (240 s, the default furnace, cached tables) is stepped with each part wrapped in a timer;
the median and the mean per sample are reported per part (indented: parts of those parts), with the EKF's
covariance propagation P = Phi P Phi^T + Q (eq. 15, :func:`twin.estimation.ekf.propagate_covariance`) as the
floor: the one piece of per-sample work that is O(n^3) and cannot be skipped.  The wrappers add about a
microsecond a call; the shares, not the absolute figures, are what a loaded machine reports truly.

The last line bounds the loop's speed with its results unchanged: ``RESULT_PARTS`` are the parts that compute
what a run records (the plant, the filter's model, Jacobian, propagation and update, the reported covariance's
propagation, the MPC's QP solve); t_s over the sum of their medians is the real-time factor the loop could reach
if everything else (condensing, fault detection, guards, the record, the loop's own work) cost nothing.

    python -m benchmarks.budget [--duration S] [--config NAME] [--json]
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

#: the controller's part: a re-plan installs a new controller object, whose calls are timed as well
CONTROLLER = "controller (MPC / LQG)"
#: (label, owner attribute of the loop or None for the loop itself, method name): the parts of a sample
PARTS: tuple[tuple[str, str | None, str], ...] = (
    ("furnace: read TCs", "furnace", "read"),
    ("furnace: advance plant t_s", "furnace", "apply"),
    ("fault detection: reading tests", "detector", "screen"),
    ("EKF update (13)", "estimators", "update"),
    ("fault detection: GLR update", "detector", "update"),
    (CONTROLLER, "controller", "control_at"),
    ("field sigma (reported P)", "uncertainty", "field_sigma"),
    ("field mean sigma", "uncertainty", "mean_sigma"),
    ("shadow / calibration outputs", "estimators", "outputs"),
    ("divergence guard", "_guard", "check"),
    ("record append", "record", "append"),
    ("EKF predict (14), (15)", "estimators", "predict"),
    ("fault detection: GLR predict", "detector", "predict"),
    ("re-plan, inline (OCP, gains: the calibrated model's plan)", "changes", "request"),
)
FLOOR = "  of which covariance propagation (15)"
#: parts inside the parts above (label, dotted owner from the loop, method name): not added to "other"
NESTED: tuple[tuple[str, str, str], ...] = (
    ("  of which model evaluate F (14)", "estimator.model", "evaluate"),
    ("  of which Jacobian Phi (16) assembly", "estimator", "_jacobian"),
    ("  of which reported P predict (issue 25)", "estimator.reported", "predict"),
    ("  of which reported P update + NIS", "estimator.reported", "update"),
    ("  of which MPC QP solve (OSQP)", "controller.solver", "solve"),
)
MPC_CONDENSE = "  of which MPC condensing (condensed_qp)"
#: the parts that compute what a run records, as implemented (the largest already BLAS or OSQP's C code): with the
#: results unchanged a sample costs at least the sum of their medians, even if everything else were free
RESULT_PARTS = ("furnace: advance plant t_s", "EKF update (13)", "  of which model evaluate F (14)",
                "  of which Jacobian Phi (16) assembly", FLOOR, "  of which reported P predict (issue 25)",
                "  of which MPC QP solve (OSQP)")
CEILING = "ceiling: the result parts alone"


def _timed(fn: Callable[..., Any], into: list[float]) -> Callable[..., Any]:
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            into.append(time.perf_counter() - t0)

    return wrapper


def time_adopted_controllers(loop: Any, into: list[float]) -> None:
    """Time the ``control_at`` of every controller the loop adopts from now on: a re-plan (the default furnace
    re-plans once its lamp efficiency is calibrated) installs a new controller object, whose calls would
    otherwise fall into "other" (as they did before stop 40: the controller's row counted 0.57 calls a sample)."""
    adopt = loop.adopt

    def adopt_timed(*args: Any, **kwargs: Any) -> None:
        adopt(*args, **kwargs)
        loop.controller.control_at = _timed(loop.controller.control_at, into)

    loop.adopt = adopt_timed


def sample_budget(cfg: Any, radiation: Any, duration: float = 240.0) -> dict[str, dict[str, float]]:
    """``{part: {"median_ms", "mean_ms", "share"}}`` per sample of one default run, with ``"step"`` (the whole
    :meth:`ClosedLoop.step`) and ``"other"`` (step minus the parts); share = mean / mean step."""
    import twin.control.mpc as mpc
    import twin.estimation.joint as joint
    from twin.runs.loop import ClosedLoop
    from twin.scenario import Scenario

    loop = ClosedLoop(cfg, Scenario(duration=duration), radiation)
    times: dict[str, list[float]] = {label: [] for label, _, _ in PARTS}
    times[FLOOR] = []
    times[MPC_CONDENSE] = []
    for label, owner, name in PARTS:
        obj = getattr(loop, owner) if owner else loop
        if obj is not None and hasattr(obj, name):
            setattr(obj, name, _timed(getattr(obj, name), times[label]))
    nested = []
    for label, path, name in NESTED:  # these objects live through a default run (no re-plan replaces them)
        inside: Any = loop
        for attr in path.split("."):
            inside = getattr(inside, attr, None)
        if inside is not None and hasattr(inside, name):
            times[label] = []
            nested.append(label)
            setattr(inside, name, _timed(getattr(inside, name), times[label]))
    time_adopted_controllers(loop, times[CONTROLLER])
    floor = joint.propagate_covariance
    joint.propagate_covariance = _timed(floor, times[FLOOR])  # type: ignore[assignment]
    condense = mpc.condensed_qp
    mpc.condensed_qp = _timed(condense, times[MPC_CONDENSE])  # type: ignore[assignment]
    step: list[float] = []
    try:
        while not loop.done:
            t0 = time.perf_counter()
            loop.step()
            step.append(time.perf_counter() - t0)
    finally:
        joint.propagate_covariance = floor  # type: ignore[assignment]
        mpc.condensed_qp = condense  # type: ignore[assignment]
        loop.close()
    n = len(step)
    total = float(np.sum(step))
    out: dict[str, dict[str, float]] = {}

    def row(values: list[float] | np.ndarray, calls: int) -> dict[str, float]:
        v = np.asarray(values, float)
        return {"median_ms": 1e3 * float(np.median(v)) if v.size else 0.0, "mean_ms": 1e3 * float(v.sum()) / n,
                "share": float(v.sum()) / total, "calls_per_sample": calls / n}

    out["step"] = row(step, n)
    parts_sum = 0.0
    inner = (FLOOR, MPC_CONDENSE, *nested)
    for label in (*[p[0] for p in PARTS], *inner):
        out[label] = row(times[label], len(times[label]))
        if label not in inner:
            parts_sum += float(np.sum(times[label]))
    out["other (loop's own work)"] = {"median_ms": float("nan"), "mean_ms": 1e3 * (total - parts_sum) / n,
                                      "share": (total - parts_sum) / total, "calls_per_sample": 1.0}
    floor_ms = sum(out[label]["median_ms"] for label in RESULT_PARTS if label in out)
    t_s = float(cfg.sampling.t_s)
    out[CEILING] = {"median_ms": floor_ms, "mean_ms": float("nan"), "share": float("nan"),
                    "calls_per_sample": float("nan"), "rtf": 1e3 * t_s / floor_ms,
                    "rtf_median_step": 1e3 * t_s / out["step"]["median_ms"]}
    return out


def format_budget(budget: dict[str, dict[str, float]]) -> str:
    w = max(len(label) for label in budget)
    lines = [f"{'part':{w}s} {'median ms':>10s} {'mean ms':>9s} {'share':>7s} {'calls':>6s}"]
    for label, r in budget.items():
        lines.append(f"{label:{w}s} {r['median_ms']:10.3f} {r['mean_ms']:9.3f} {100 * r['share']:6.1f}% "
                     f"{r['calls_per_sample']:6.2f}")
    c = budget.get(CEILING)
    if c is not None:
        lines.append(f"rtf at the median step {c['rtf_median_step']:.0f}; with the result parts alone (all else free) "
                     f"at most {c['rtf']:.0f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.budget", description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=240.0)
    p.add_argument("--config", default=None, help="furnace TOML or shipped name (default: default)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    from twin.config import load_config
    from twin.radiation import radiation_model

    cfg = load_config(args.config)
    budget = sample_budget(cfg, radiation_model(cfg), args.duration)
    sys.stdout.write((json.dumps(budget) if args.json else format_budget(budget)) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
