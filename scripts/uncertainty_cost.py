"""What the reported uncertainty costs per sample (issue 25): ``step_ms`` (the bench's: estimator update + predict
+ controller, median) with ``[ekf.model_error]`` and without it (the filter's own P reported), interleaved in one
process, and the sigma map's own time per sample (outside ``step_ms``: it is computed for the snapshot).

    python scripts/uncertainty_cost.py [--config default] [--duration 60] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    from twin.config import load_config
    from twin.radiation import radiation_model
    from twin.runs.loop import ClosedLoop
    from twin.scenario import Scenario

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="default")
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    cfg = load_config(None if args.config == "default" else args.config)
    rad = radiation_model(cfg)
    variants = {"reported": cfg, "filter_P": cfg.with_overrides({"ekf.model_error": None})}
    step: dict[str, list[float]] = {k: [] for k in variants}
    sigma_ms: list[float] = []
    for _ in range(args.repeats):
        for name, c in variants.items():
            loop = ClosedLoop(c, Scenario(duration=args.duration), rad)
            for _ in loop.run():
                pass
            loop.close()
            step[name].append(float(np.median(loop.compute_ms)))
            P = loop.estimator.reported_P
            t0 = time.perf_counter()
            for _ in range(200):
                loop.uncertainty.field_sigma(P)
                loop.uncertainty.mean_sigma(P)
            sigma_ms.append(1000.0 * (time.perf_counter() - t0) / 200)
    out = {f"step_ms_{k}": float(np.median(v)) for k, v in step.items()}
    out["step_ratio"] = out["step_ms_reported"] / out["step_ms_filter_P"]
    out["sigma_map_ms"] = float(np.median(sigma_ms))
    sys.stdout.write(json.dumps(out) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
