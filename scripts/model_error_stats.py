"""Measure the model-error statistics of ``[ekf.model_error]`` and check the reported uncertainty (issue 25).

    python scripts/model_error_stats.py measure --config default --oscillate --seeds 10 11 12 \\
        --references 1000:90 1050:150 --runs /tmp/me-runs
    python scripts/model_error_stats.py check --config banded --seeds 50 51 --references 1100:120 --runs /tmp/me-runs

``measure`` runs the closed loop against the honest truth for each seed and reference (duration 2 t_E; a run
already in ``--runs`` is reused) and prints the one-step defect's fitted q0, q1 and the representation rms
(:mod:`twin.experiments.model_error_stats`) and, for each ``--scales`` factor on q0 (with the furnace file's TC
tolerance, ``[ekf.model_error] tc_tolerance_*``), the coverage, NEES and NIS of the runs replayed with it.
``check`` prints the metrics of the runs replayed with the furnace file's ``[ekf.model_error]`` as a Markdown
table (``docs/uncertainty.md``).  ``scale`` prints, for each ``--scales`` factor k on the runs' stored sigma, each
run's steady coverage, the pooled one and how many runs are in 90-99 %, with the error's split into one offset per
run and the rest (:func:`twin.experiments.model_error_stats.coverage_by_scale`):

    python scripts/model_error_stats.py scale --config default --oscillate --seeds 0 1 2 3 4 \
        --scales 0.6 0.8 0.9 1 1.1 1.25 --runs /tmp/me-runs
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

KEYS = ("coverage_2sigma_transient", "coverage_2sigma_steady", "nees_mean", "nis_mean",
        "field_estimation_error_steady_max", "tc4_error_steady_max")


def run_once(cfg: Any, furnace: str, osc: bool, seed: int, setpoint: float, t_E: float, folder: Path) -> Path:
    from twin.runs.loop import ClosedLoop
    from twin.runs.record import save_arrays
    from twin.scenario import Scenario

    path = folder / f"{furnace}-{'osc' if osc else 'fixed'}-{seed}-{int(setpoint)}-{int(t_E)}.npz"
    if not path.exists():
        sc = Scenario(reference={"setpoint": setpoint, "t_E": t_E}, duration=2 * t_E, oscillation={"enabled": osc},
                      seed=seed)
        loop = ClosedLoop(cfg, sc)
        for _ in loop.run():
            pass
        save_arrays(path, loop.timeseries())
    return path


def main(argv: list[str] | None = None) -> int:
    from twin.config import load_config
    from twin.estimation.choice import estimator_model
    from twin.experiments.model_error_stats import (
        bias_statistics,
        coverage_by_scale,
        model_error_statistics,
        replay_metrics,
        replay_variants,
    )
    from twin.model.tables import model_tables
    from twin.radiation import radiation_model
    from twin.runs.record import load_arrays
    from twin.scenario import EstimatorChoice, Scenario

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("measure", "check", "scale"))
    ap.add_argument("--config", default="default")
    ap.add_argument("--oscillate", action="store_true")
    ap.add_argument("--seeds", type=int, nargs="+", required=True)
    ap.add_argument("--references", nargs="+", default=["1100:120"], help="setpoint:t_E pairs (K:s)")
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 5.0, 20.0])
    ap.add_argument("--bias-degree", type=int, default=None,
                    help="measure: also the model's constant bias of this Legendre degree (bias_statistics)")
    ap.add_argument("--bias-scales", type=float, nargs="+", default=[1.0],
                    help="measure: factors on the measured bias variances (with the white rest of the defect)")
    ap.add_argument("--bias-growth", action="store_true",
                    help="measure: the bias grows with the temperature (its exponent fitted to the runs)")
    ap.add_argument("--runs", type=Path, required=True, help="folder for the runs' time series (reused)")
    args = ap.parse_args(argv)
    cfg = load_config(None if args.config == "default" else args.config)
    args.runs.mkdir(parents=True, exist_ok=True)
    refs = [tuple(float(v) for v in r.split(":")) for r in args.references]
    paths = [run_once(cfg, args.config, args.oscillate, s, sp, tE, args.runs) for s in args.seeds for sp, tE in refs]
    runs = [load_arrays(p) for p in paths]
    if args.what == "scale":
        out = coverage_by_scale(runs, args.scales)
        lines = [f"run means {', '.join(f'{a:+.2f}' for a in out['run_mean'])} K; within-run sd "
                 f"{', '.join(f'{s:.2f}' for s in out['within_sd'])} K; rho = {out['rho']:.2f}; runs in 90-99 % "
                 f"with an exact sigma for such an error: {100 * out['perfect_in_band']:.0f} %", "",
                 "| k | " + " | ".join(f"seed {s}" for s in args.seeds)
                 + " | pooled | runs in 90-99 % | transient, min |",
                 "|---" * (len(args.seeds) + 4) + "|"]
        for r in out["rows"]:
            lines.append(f"| {r['k']:g} | " + " | ".join(f"{100 * c:.1f}" for c in r["steady"])
                         + f" | {100 * r['pooled']:.1f} | {r['in_band']} of {len(runs)} "
                         f"| {100 * r['transient_min']:.1f} |")
        sys.stdout.write("\n".join(lines) + "\n")
        return 0
    tables = model_tables(cfg, radiation_model(cfg))
    if args.what == "measure":
        def model_for(ts: Any) -> Any:
            sc = Scenario.model_validate_json(str(ts["scenario"]))
            return estimator_model(EstimatorChoice(calibrate=False), tables, sc.oscillation, cfg)

        stats = model_error_statistics(cfg, runs, model_for)
        sys.stdout.write(json.dumps(stats) + "\n")
        base = cfg.ekf.model_error.model_dump() if cfg.ekf.model_error is not None else {}
        # every variant in the run's own mode (no [ekf.model_error.oscillating]: its fields stand for both)
        base.update(oscillating=None, bias_degree=0, bias_variance=(), bias_node_variance=0.0)
        # each scale of the measured one-step q0 alone (white), with the furnace file's TC tolerance (consider
        # states; 0 = none)
        labels = [{"scale": c} for c in args.scales]
        mes = [{**base, "q0": c * stats["q0"], "q1": stats["q1"], "representation_rms": stats["representation_rms"]}
               for c in args.scales]
        if args.bias_degree is not None:
            # the model's bias as consider states (shape and per node) and the white rest of the defect, each
            # --bias-scales factor on the bias's variances
            b = bias_statistics(cfg, runs, model_for, args.bias_degree, exponent=None if args.bias_growth else 0.0)
            sys.stdout.write(json.dumps(b) + "\n")
            for bs in args.bias_scales:
                labels.append({"bias_scale": bs})
                mes.append({**base, "q0": b["q0_white"], "q1": b["q1_white"],
                            "representation_rms": stats["representation_rms"], "bias_degree": args.bias_degree,
                            "bias_variance": tuple(bs * v for v in b["bias_variance"]),
                            "bias_node_variance": bs * b["bias_node_variance"],
                            "bias_temperature": b["bias_temperature"],
                            "bias_exponent": b["bias_exponent"] if args.bias_growth else 0.0})
        per_run = [replay_variants(cfg, ts, tables, mes)[0] for ts in runs]  # one filter replay per run
        for i, label in enumerate(labels):
            ms = [r[i] for r in per_run]
            sys.stdout.write(json.dumps({**label, **{k: [round(m[k], 4) for m in ms] for k in KEYS}}) + "\n")
        return 0
    # the last column: the largest |replayed - stored estimate| (K): 0 when the replay is the run's own filter
    rows = ["| run | " + " | ".join(KEYS) + " | replay deviation |", "|---" * (len(KEYS) + 2) + "|"]
    for p, ts in zip(paths, runs, strict=True):
        m, deviation = replay_metrics(cfg, ts, tables)
        cells = [f"{m[k]:.3f}" if k.startswith(("coverage", "nees", "nis")) else f"{100 * m[k]:.2f} %" for k in KEYS]
        rows.append(f"| {p.stem} | " + " | ".join(cells) + f" | {deviation:.1e} K |")
    sys.stdout.write("\n".join(rows) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
