"""Why a CI run over OPC UA gave 1.301 % steady mean error, 1.587 % in process: ``python scripts/opcua_stall.py``.

The test's scenario (small furnace, 700 K in t_E = 12 s, 24 s, seed 4, the paper's estimator) in process, with
what a stall of the twin's loop thread does to a furnace over OPC UA: the furnace holds the last command until
its watchdog trips (1 s after the last write, product.md), then its lamps are off until the twin writes again;
the samples of the stall wait in the twin's buffer and are taken complete afterwards, so none counts as late.
Beside it, what commit 4ebefe4 guessed (the emulator's clock shifting the lamp commands by a sample).

Measured over OPC UA in real time (the emulator in its own process, the twin through the REST API, a stall of
1.4 s injected at t = 5 s into the twin's read): 1.176 %, no late sample, one interlock trip; this table's
1.4 s at 5 s gives 1.184 %.

Usage::

    python scripts/opcua_stall.py [--at 2 5 8] [--stall 1.0 1.2 1.3 1.4] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np

from twin.config import small_config
from twin.furnace.simulated import SimulatedFurnace
from twin.runs.loop import ClosedLoop
from twin.scenario import PAPER_ESTIMATOR, Scenario

WATCHDOG_S = 1.0  # the furnace's interlock (product.md)
SCENARIO = {"reference": {"setpoint": 700.0, "t_E": 12.0}, "duration": 24.0, "seed": 4, "tc_noise": 1.0,
            "estimator": PAPER_ESTIMATOR.model_dump()}


class Stalled:
    """A simulated furnace as an OPC UA furnace sees a twin stalled for ``d`` s from ``t_a``: it holds the last
    command for the watchdog's second, then its lamps are off (``d = 0``: no stall); ``delay``: every command
    one sample late instead (the emulator's clock shifting it)."""

    def __init__(self, inner: SimulatedFurnace, t_a: float = 0.0, d: float = 0.0, delay: bool = False) -> None:
        self.inner, self.t_a, self.d, self.delay = inner, t_a, d, delay
        self.kind, self.realtime, self.t_s, self.tc_positions = "test", False, inner.t_s, inner.tc_positions
        self.held: np.ndarray | None = None
        self.previous = np.zeros(6)

    def read(self, t: float) -> Any:
        return self.inner.read(t)

    def apply(self, u: Any, t: float) -> None:
        u = np.asarray(u, float)
        if self.delay:
            u, self.previous = self.previous, u.copy()
        elif self.t_a <= t < self.t_a + self.d - 1e-9:
            self.held = u.copy() if self.held is None else self.held
            u = self.held if t < self.t_a + WATCHDOG_S - 1e-9 else np.zeros_like(u)
        self.inner.apply(u, t)

    def motion(self, t: float) -> Any:
        return self.inner.motion(t)

    def set_oscillation(self, spec: Any, t: float) -> None:
        self.inner.set_oscillation(spec, t)

    def true_field(self) -> Any:
        return self.inner.true_field()

    def drain_events(self) -> tuple[str, ...]:
        return ()

    def close(self) -> None:
        return None


def steady_error(radiation: Any, **stall: Any) -> float:
    """The run's ``mean_error_steady_max`` (fraction of the setpoint) with the furnace as ``Stalled(**stall)``."""
    cfg = small_config()
    scenario = Scenario.model_validate(SCENARIO)
    furnace = Stalled(SimulatedFurnace.for_scenario(cfg, scenario, radiation), **stall)
    loop = ClosedLoop(cfg, scenario, radiation, furnace=furnace)
    list(loop.run())
    return float(loop.metrics()["mean_error_steady_max"])


def main(argv: list[str] | None = None) -> int:
    from twin.radiation import radiation_model

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--at", type=float, nargs="+", default=[2.0, 5.0, 8.0, 11.0])
    p.add_argument("--stall", type=float, nargs="+", default=[1.0, 1.1, 1.2, 1.3, 1.4, 1.6])
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    rad = radiation_model(small_config())
    out: dict[str, Any] = {"in_process": steady_error(rad), "one_sample_delay": steady_error(rad, delay=True),
                           "stalls": []}
    for t_a in args.at:
        row = [steady_error(rad, t_a=t_a, d=d) for d in args.stall]
        out["stalls"].append({"at": t_a, "stall_s": args.stall, "steady": row})
        print(f"stall at {t_a:4.1f} s: " + " ".join(f"{d:g} s -> {100 * v:.3f} %" for d, v in  # noqa: T201
                                                      zip(args.stall, row, strict=True)), flush=True)
    print(f"no stall: {100 * out['in_process']:.3f} %; every command a sample late: "  # noqa: T201
          f"{100 * out['one_sample_delay']:.3f} %")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
