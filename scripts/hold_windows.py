"""A long hold, without and with the calibration's re-plan (docs/control.md, "Within a run").

    python scripts/hold_windows.py default fixed 25 1100 120 480
    python scripts/hold_windows.py default oscillating 28 1000 90 360

FURNACE MODE SEED SETPOINT T_E DURATION: one run of the reference (setpoint K in t_E s, held to DURATION s) against
the simulated furnace's own truth (``truth = "independent"``), with ``calibration.controller_follows`` false and
then true.  Prints, per run, the re-plans and, over three windows (the metrics' steady window 1.5-2 t_E, then up
to DURATION - 120 s, then the last 120 s), the true fillet mean's largest error and the true T_sup (max |T - T_ref|
over the fillet), both relative to the setpoint, from the true field at each whole second.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def run(furnace: str, mode: str, seed: int, setpoint: float, t_E: float, duration: float, follows: bool) -> dict:
    from control_table import _patient_plans  # the first plan's wall-time limit raised, as for the table

    from twin.config import load_config
    from twin.furnace.simulated import SimulatedFurnace
    from twin.limits import scenario_limits
    from twin.physics.fillet import Fillet
    from twin.radiation import radiation_model
    from twin.runs.loop import ClosedLoop
    from twin.scenario import parse_scenario

    _patient_plans()
    cfg = load_config(furnace).with_overrides({"calibration.controller_follows": follows})
    rad, fillet = radiation_model(cfg), Fillet.of(cfg)
    spec = {"reference": {"setpoint": setpoint, "t_E": t_E}, "duration": duration, "seed": seed,
            "truth": "independent", "oscillation": {"enabled": mode == "oscillating"}}
    scenario = parse_scenario(spec, scenario_limits(cfg))
    loop = ClosedLoop(cfg, scenario, rad, furnace=SimulatedFurnace.for_scenario(cfg, scenario, rad))
    rows, replans = [], []
    for s in loop.run():
        replans += [e for e in s.events if e.startswith("calibration at")]
        if s.field_true is not None and abs(s.t - round(s.t)) < 1e-6:
            rows.append((s.t, abs(s.true_mean - s.T_ref) / setpoint, fillet.sup(s.field_true, s.T_ref) / setpoint))
    a = np.array(rows)
    out: dict = {"follows": follows, "replans": replans}
    for lo, hi in ((1.5 * t_E, 2 * t_E), (2 * t_E, duration - 120.0), (duration - 120.0, duration)):
        w = (a[:, 0] >= lo) & (a[:, 0] <= hi)
        if w.any() and hi > lo:
            out[f"{lo:.0f}-{hi:.0f} s"] = {"true mean error max %": round(100 * a[w, 1].max(), 3),
                                           "true T_sup max %": round(100 * a[w, 2].max(), 3)}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("furnace")
    p.add_argument("mode", choices=["fixed", "oscillating"])
    p.add_argument("seed", type=int)
    p.add_argument("setpoint", type=float)
    p.add_argument("t_E", type=float)
    p.add_argument("duration", type=float)
    args = p.parse_args(argv)
    for follows in (False, True):
        result = run(args.furnace, args.mode, args.seed, args.setpoint, args.t_E, args.duration, follows)
        sys.stdout.write(json.dumps(result) + "\n")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
