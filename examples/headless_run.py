"""A headless closed-loop run with a reference of your own, its files in a folder.

    python examples/headless_run.py --out runs/ramp            # the default furnace, 300 s
    python examples/headless_run.py --small --duration 20      # the small test furnace, 20 s

The reference is a list of (time s, temperature K) points, joined smoothly (``PointsReference``); the loop
reads the simulated furnace's thermocouples, estimates the field (EKF), plans and controls the lamps, and
writes ``scenario.json``, ``timeseries.npz`` and ``metrics.json`` to ``--out``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import twin


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="the small test furnace (fast)")
    ap.add_argument("--duration", type=float, default=300.0, help="run time in s")
    ap.add_argument("--out", type=Path, default=None, help="run folder (default: a temporary one)")
    args = ap.parse_args(argv)

    cfg = twin.small_config() if args.small else twin.load_config()
    d = args.duration
    # from the start temperature to 700 K at a quarter of the run, 1000 K at half of it, then hold; the metrics'
    # windows follow the last point t_E = d / 2: transient up to t_E, steady from 1.5 t_E to 2 t_E = d
    scenario = twin.parse_scenario({
        "reference": {"points": [[0.25 * d, 700.0], [0.5 * d, 1000.0]]},
        "duration": d,
        "oscillation": {"enabled": True},
    })
    out = args.out or Path(tempfile.mkdtemp(prefix="furnace-twin-run-"))
    session = twin.RunSession(twin.ClosedLoop(cfg, scenario), twin.RunFolder(out))
    metrics = session.run()
    series = twin.load_arrays(session.folder.timeseries)  # the same arrays as timeseries.npz
    print(f"{metrics['status']}: {len(series['t'])} samples in {out}")  # noqa: T201
    # relative to the last setpoint (twin.runs.metrics); true_*: against the simulated furnace's own field
    for key in ("mean_error_steady_max", "true_mean_error_steady_max", "true_inhomogeneity_steady"):
        print(f"  {key:28s} {100 * metrics[key]:.2f} %")  # noqa: T201
    return {**metrics, "out": out}


if __name__ == "__main__":
    main()
