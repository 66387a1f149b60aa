"""The paper's measurement campaign (section 5): fixed / oscillating specimen x three TC4 positions.

``furnace-twin campaign`` runs the six experiments with the default scenario (t_E = 120 s,
runs of 2 t_E, eta = 3 L_h sin(2 pi t / Pi) with Pi = 0.15 t_E when oscillating), writes each
run's folder, a table ``campaign.md`` putting the paper's reported numbers beside the twin's,
``campaign.json`` (the ``--json`` output of product.md), and the Fig. 9 comparison.
"""

from __future__ import annotations

import json
import logging
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.config import FurnaceConfig
from twin.limits import scenario_limits
from twin.runs.metrics import METRIC_KEYS
from twin.scenario import Scenario, parse_scenario

if TYPE_CHECKING:
    from twin.runs.runner import SinkFactory

log = logging.getLogger(__name__)

TC4_POSITIONS: tuple[tuple[float, float], ...] = ((0.375, 0.5), (0.5, 0.5), (0.625, 0.5))

#: Numbers the paper reports (section 5 text and Figs. 4, 6, 9), as fractions of T_ref(t_E).
PAPER: dict[str, dict[str, float]] = {
    "fixed": {
        "mean_error_transient_max": 0.02,
        "mean_error_steady_max": 0.005,
        "tc4_error_transient_max": 0.015,
        "tc4_error_steady_max": 0.005,
        "inhomogeneity_transient_max": 0.10,
        "inhomogeneity_steady": 0.04,
    },
    "oscillating": {
        "mean_error_transient_max": 0.02,
        "mean_error_steady_max": 0.0075,
        "tc4_error_transient_max": 0.03,
        "tc4_error_steady_max": 0.03,
        "inhomogeneity_transient_max": 0.10,
        "inhomogeneity_steady": 0.02,
    },
}



def campaign_scenarios(cfg: FurnaceConfig, t_E: float = 120.0) -> list[tuple[str, Scenario]]:
    """The six experiments; the oscillation is the paper's 3 L_h sin(2 pi t / (0.15 t_E)), its amplitude
    capped at the furnace's eta_max (the furnace's default amplitude, ``twin.limits``)."""
    limits = scenario_limits(cfg)
    out = []
    for oscillating in (False, True):
        for tc4 in TC4_POSITIONS:
            name = f"{'oscillating' if oscillating else 'fixed'}_tc4_{tc4[0]:g}"
            scenario = parse_scenario({
                "reference": {"setpoint": 1100.0, "t_E": t_E},
                "duration": 2 * t_E,
                "oscillation": {"enabled": oscillating, "period": 0.15 * t_E},
                "tc4": list(tc4),
            }, limits)
            out.append((name, scenario))
    return out


def _fmt(v: float | None) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{100 * v:.2f} %"


def campaign_table(experiments: list[dict[str, Any]]) -> str:
    """Markdown table: each metric, the paper's value and the twin's per experiment."""
    head = "| metric | paper fixed | paper osc. | " + " | ".join(e["name"] for e in experiments) + " |"
    sep = "|" + "---|" * (3 + len(experiments))
    rows = [head, sep]
    for key in METRIC_KEYS:
        cells = [key, _fmt(PAPER["fixed"].get(key)), _fmt(PAPER["oscillating"].get(key))]
        cells += [_fmt(e["metrics"].get(key)) for e in experiments]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def run_campaign(
    cfg: FurnaceConfig,
    out: Path,
    t_E: float = 120.0,
    radiation: Any = None,
    sink_factories: Iterable[SinkFactory] = (),
) -> dict[str, Any]:
    """Run the six experiments; return the product.md ``campaign --json`` object.

    The three runs of each specimen mode start identically, so their first plan is solved once.
    """
    from twin.radiation import radiation_model
    from twin.runs.figures import plot_homogeneity_comparison
    from twin.runs.loop import ClosedLoop
    from twin.runs.runner import _json_safe, execute_run

    plan_cache: dict[Any, Any] = {}
    sinks = list(sink_factories)
    rad = radiation if radiation is not None else radiation_model(cfg)
    out.mkdir(parents=True, exist_ok=True)
    experiments: list[dict[str, Any]] = []
    series: dict[str, Any] = {}
    for name, scenario in campaign_scenarios(cfg, t_E):
        log.info("campaign: %s", name)
        folder = out / name
        loop = ClosedLoop(cfg, scenario, rad, plan_cache=plan_cache)
        result = execute_run(loop, folder, sink_factories=sinks)
        series[name] = loop.timeseries()
        metrics = _json_safe({k: v for k, v in result.items() if k != "out"})
        experiments.append(
            {
                "name": name,
                "oscillation": scenario.oscillation.enabled,
                "tc4": list(scenario.tc4),
                "metrics": metrics,
                "out": str(folder),
            }
        )
    pairs = [
        (f"TC4 at ({x:g} L_s, {y:g} W_s)", series[f"fixed_tc4_{x:g}"], series[f"oscillating_tc4_{x:g}"])
        for x, y in TC4_POSITIONS
    ]
    plot_homogeneity_comparison(pairs, out / "homogeneity.png")
    result = {"experiments": experiments, "paper": PAPER}
    (out / "campaign.json").write_text(json.dumps(result, indent=2))
    (out / "campaign.md").write_text(
        "# Campaign: the paper's numbers beside the twin's\n\n"
        "Relative to T_ref(t_E). Windows: transient 0..t_E, steady 1.5..2 t_E (product.md).\n\n"
        + campaign_table(experiments)
        + "\n"
    )
    return result


def campaign_command(cfg: FurnaceConfig, args: Any, sink_factories: Iterable[SinkFactory] = ()) -> int:
    t_E = float(args.t_e) if args.t_e else 120.0
    if t_E <= 1.0:
        print("furnace-twin campaign: --t-e must be > 1 s", file=sys.stderr)  # noqa: T201
        return 2
    out = Path(args.out)
    result = run_campaign(cfg, out, t_E, sink_factories=sink_factories)
    if args.json:
        print(json.dumps(result))  # noqa: T201
    else:
        sys.stdout.write(campaign_table(result["experiments"]) + "\n")
        log.info("campaign written to %s", out)
    return 0
