"""Does the recommended TC placement pay?  Closed-loop runs with ``place-tcs``'s positions against the paper's.

    python scripts/place_tcs_study.py [--furnaces default banded] [--seeds 60 61 62] [--oscillate]
                                      [--out docs/figures/place-tcs/study.json] [--docs docs/uncertainty.md]

For each furnace: ``furnace-twin place-tcs`` (fixed specimen, or ``--oscillate``) gives TC1-3; then the closed
loop runs (1100 K / 120 s over 240 s, honest truth, the default estimator) once with the paper's positions
(0.25/0.5, 0.5/0.8, 0.75/0.5) and once with the recommended ones, on the same seeds (seeds that no tuning used).
Reported per run: the field estimation error against the true field (max over the fillet, steady window, the
metric), the rms of that error over the fillet and the steady window, the true steady mean error and the 2-sigma
coverage.  The Markdown table goes between the ``<!-- place-tcs-study -->`` markers of ``--docs``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

MARK = "<!-- place-tcs-study -->"


def fillet_rms_error(ts: dict[str, Any]) -> float:
    """rms over the fillet's cells and the steady window's fields of (estimate - truth), relative to the setpoint."""
    from twin.physics.fillet import Fillet
    from twin.runs.metrics import window, windows_of

    w = windows_of(ts)
    tf = np.asarray(ts["t_field"], float)
    sel = window(tf, w.t_E, "steady", w.t0)
    fillet = Fillet.on_grid(np.asarray(ts["x"]), np.asarray(ts["y"]), float(ts["L_s"]), float(ts["W_s"]))
    err = (np.asarray(ts["field_hat"])[sel].astype(float) - np.asarray(ts["field_true"])[sel].astype(float))
    return float(np.sqrt(np.mean(err[..., fillet.mask] ** 2)) / w.setpoint)


def run_case(cfg: Any, positions: list[tuple[float, float]], seed: int, oscillate: bool,
             plans: dict[Any, Any]) -> dict[str, float]:
    """One closed-loop run with TC1-3 at ``positions``; ``plans`` is shared by the runs of one furnace (the first
    plan does not depend on where the TCs are: the initial estimate is the uniform start, so it is solved once)."""
    from twin.runs.loop import ClosedLoop
    from twin.scenario import Scenario

    placed = cfg.with_overrides({f"sensors.tc{i + 1}": list(p) for i, p in enumerate(positions)})
    loop = ClosedLoop(placed, Scenario(seed=seed, oscillation={"enabled": oscillate}), plan_cache=plans)
    for _ in loop.run():
        pass
    ts = loop.timeseries()
    m = loop.metrics()
    return {"field_estimation_error_steady_max": m["field_estimation_error_steady_max"],
            "field_estimation_error_steady_rms": fillet_rms_error(ts),
            "true_mean_error_steady_max": m["true_mean_error_steady_max"],
            "coverage_2sigma_steady": m["coverage_2sigma_steady"]}


def table(result: dict[str, Any]) -> str:
    lines = ["| furnace | TC1-3 (x/L_s, y/W_s) | field est. error, steady max (mean over seeds) | same, rms | "
             "true mean error, steady | 2σ coverage, steady |", "|---|---|---|---|---|---|"]
    for furnace, r in result["furnaces"].items():
        for name in ("paper", "recommended"):
            runs = r["runs"][name]
            pos = ", ".join(f"{x:.3f}/{y:.2f}" for x, y in r["positions"][name])

            def mean(k: str, runs: list[dict[str, float]] = runs) -> float:
                return float(np.mean([c[k] for c in runs]))

            spread = ", ".join(f"{100 * c['field_estimation_error_steady_max']:.2f}" for c in runs)
            lines.append(f"| {furnace} | {name}: {pos} | {100 * mean('field_estimation_error_steady_max'):.2f} % "
                         f"({spread}) | {100 * mean('field_estimation_error_steady_rms'):.3f} % | "
                         f"{100 * mean('true_mean_error_steady_max'):.2f} % | {mean('coverage_2sigma_steady'):.3f} |")
    mode = "oscillating" if result["oscillate"] else "fixed"
    seeds = ", ".join(str(s) for s in result["seeds"])
    cmd = ("python scripts/place_tcs_study.py --seeds " + " ".join(str(s) for s in result["seeds"])
           + (" --oscillate" if result["oscillate"] else "") + " --docs docs/uncertainty.md")
    return (f"Closed loop 1100 K / 120 s, {mode} specimen, honest truth, seeds {seeds} (`{cmd}`):\n\n"
            + "\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    from twin.config import load_config
    from twin.experiments.place_tcs import PAPER_TC123, rank_positions

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--furnaces", nargs="+", default=["default", "banded"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[60, 61, 62])
    ap.add_argument("--oscillate", action="store_true")
    ap.add_argument("--out", type=Path, default=Path("docs/figures/place-tcs/study.json"))
    ap.add_argument("--docs", type=Path, default=None, help="write the table between the markers of this file")
    ap.add_argument("--table-only", action="store_true", help="only the table of the furnaces already in --out")
    args = ap.parse_args(argv)
    result: dict[str, Any] = {"seeds": args.seeds, "oscillate": args.oscillate, "furnaces": {}}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    done = json.loads(args.out.read_text()) if args.out.exists() else {}
    if done.get("seeds") == args.seeds and done.get("oscillate") == args.oscillate:
        result["furnaces"].update(done["furnaces"])  # resume: the furnaces measured before
    for furnace in args.furnaces:
        if furnace in result["furnaces"] or args.table_only:
            continue
        cfg = load_config(None if furnace == "default" else furnace)
        rec = rank_positions(cfg, count=3, oscillate=args.oscillate)
        positions = {"paper": [tuple(p) for p in PAPER_TC123],
                     "recommended": [(p["x_rel"], p["y_rel"]) for p in rec["positions"]]}
        plans: dict[Any, Any] = {}
        runs = {name: [run_case(cfg, pos, s, args.oscillate, plans) for s in args.seeds]
                for name, pos in positions.items()}
        result["furnaces"][furnace] = {"positions": positions, "runs": runs,
                                       "information": {"paper": rec["baseline"]["paper"],
                                                       "recommended": rec["positions"][-1]["score"]}}
        result["furnaces"] = {f: result["furnaces"][f] for f in args.furnaces if f in result["furnaces"]}
        args.out.write_text(json.dumps(result, indent=1) + "\n")  # kept furnace by furnace
        sys.stderr.write(f"{furnace}: done\n")
    text = table(result)
    if args.docs is not None:
        doc = args.docs.read_text()
        head, _, rest = doc.partition(MARK)
        _, _, tail = rest.partition(MARK)
        args.docs.write_text(head + MARK + "\n" + text + MARK + tail)
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
