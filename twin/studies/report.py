"""``study.md``: what a user reads first — the best case per metric, percentiles, failures, figures, timing.

Metrics are errors (smaller is better) in % of the setpoint T_ref(t_E).  With a grid and Monte Carlo
samples, "best" is the grid point with the smallest median over the samples.
"""

from __future__ import annotations

import json
import time
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from twin.runs.folder import write_atomic
from twin.runs.metrics import METRIC_KEYS
from twin.studies.spec import StudySpec

REPORT_PERCENTILES = (5, 25, 50, 75, 95)


def _pct(v: float | None) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{100 * v:.2f} %"


def _value(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, float) else json.dumps(v)


def _params(p: Mapping[str, Any]) -> str:
    return ", ".join(f"{k} = {_value(v)}" for k, v in p.items()) or "(base)"


def _metric_keys(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    present = {k for r in rows for k, v in (r.get("metrics") or {}).items() if isinstance(v, (int, float))}
    return [k for k in METRIC_KEYS if k in present]


def _finished(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    return [r for r in rows if r["status"] in ("done", "skipped") and r.get("metrics")]


#: a grid field that only replicates a design point (TC-noise seed): not part of the point, its spread is the noise
REPLICATE_FIELD = "seed"


def design_fields(spec: StudySpec) -> list[str]:
    """The grid fields that make a design point: every grid field but ``seed``, whose values (like the Monte
    Carlo samples) are replicates of one point."""
    return [p for p in spec.grid if p != REPLICATE_FIELD]


def point_values(spec: StudySpec, rows: Sequence[Mapping[str, Any]],
                 metric: str) -> list[tuple[dict[str, Any], list[float], list[str]]]:
    """Per design point (in the order met): its parameters, the metric over its finished replicates, and their
    case keys."""
    fields = design_fields(spec)
    groups: dict[str, tuple[dict[str, Any], list[float], list[str]]] = {}
    for r in _finished(rows):
        v = r["metrics"].get(metric)
        if v is None or not np.isfinite(v):
            continue
        point = {p: r["params"][p] for p in fields}
        g = groups.setdefault(json.dumps(point, sort_keys=True), (point, [], []))
        g[1].append(float(v))
        g[2].append(r["key"])
    return list(groups.values())


def replicate_spread(groups: Sequence[tuple[Any, list[float], Any]]) -> tuple[float | None, int]:
    """The seed-to-seed spread of a metric: the median over the design points run with two or more replicates
    of their range (max - min), and how many points had replicates; None when no point had."""
    ranges = [max(v) - min(v) for _, v, _ in groups if len(v) >= 2]
    return (float(np.median(ranges)) if ranges else None), len(ranges)


def best_cases(spec: StudySpec, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per metric: the design points ranked by their median over the replicates (seeds, Monte Carlo samples).

    ``value``/``params``/``n`` are the best point's; ``key`` its case when it ran once.  ``decided`` is true only
    when the best point's median is below the next one's by more than the seed-to-seed spread
    (:func:`replicate_spread`): a smaller difference, or no replicates to measure the spread, names no best case.
    ``min``/``max`` span the points' medians (the range every map of the metric is coloured over)."""
    out = []
    for m in _metric_keys(_finished(rows)):
        groups = point_values(spec, rows, m)
        if not groups:
            continue
        ranked = sorted(groups, key=lambda g: float(np.median(g[1])))
        medians = [float(np.median(g[1])) for g in ranked]
        spread, replicated = replicate_spread(groups)
        best = ranked[0]
        margin = medians[1] - medians[0] if len(ranked) > 1 else None
        out.append({"metric": m, "value": medians[0], "params": best[0], "key": best[2][0] if len(best[1]) == 1
                    else None, "n": len(best[1]),
                    "next": {"value": medians[1], "params": ranked[1][0]} if len(ranked) > 1 else None,
                    "margin": margin, "spread": spread, "replicated_points": replicated, "points": len(ranked),
                    "decided": margin is not None and spread is not None and margin > spread,
                    "min": medians[0], "max": medians[-1]})
    return out


def best_sentence(b: Mapping[str, Any]) -> str:
    """What the study says about a metric's best point, in words (study.md; the view says the same)."""
    if b["points"] < 2:
        return "one design point: nothing to choose between"
    if b["spread"] is None:
        return (f"no best case: each point ran once, so the seed-to-seed spread is unknown (best {_pct(b['value'])}"
                f" at {_params(b['params'])}, next {_pct(b['next']['value'])})")
    if not b["decided"]:
        return (f"no case is better than the seed spread of {_pct(b['spread'])} (best and next differ by "
                f"{_pct(b['margin'])})")
    return (f"best {_pct(b['value'])} at {_params(b['params'])}: {_pct(b['margin'])} below the next, more than "
            f"the seed spread of {_pct(b['spread'])}")


def percentiles(rows: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    """Per metric over the finished cases: p5, p25, p50, p75, p95, mean and max (fractions)."""
    done = _finished(rows)
    out = {}
    for m in _metric_keys(done):
        v = np.array([r["metrics"][m] for r in done if r["metrics"].get(m) is not None], float)
        if v.size:
            out[m] = {**{f"p{q}": float(np.percentile(v, q)) for q in REPORT_PERCENTILES},
                      "mean": float(v.mean()), "max": float(v.max()), "n": int(v.size)}
    return out


def write_report(path: Path, spec: StudySpec, furnace: str, summary: Mapping[str, Any]) -> Path:
    rows = summary["cases"]
    lines = [f"# Study: {spec.name or path.parent.name}", ""]
    lines += [f"- furnace: `{furnace}`", f"- cases: {len(rows)} ({summary['computed']} computed now, "
              f"{summary['skipped']} found done earlier, {summary['failed']} failed, {summary['pending']} pending)",
              f"- results: `{Path(summary['results']).name}` (and `results.csv`)"]
    for i, inv in enumerate(summary.get("invocations") or [summary], 1):
        when = time.strftime("%Y-%m-%d %H:%M", time.localtime(inv["at"])) if "at" in inv else ""
        lines.append(f"- invocation {i} {when}: {inv['computed']} cases computed ({inv['failed']} failed), "
                     f"{inv['skipped']} found done, {inv['pending']} left pending; {inv['workers']} workers, "
                     f"{inv['wall_s']:.1f} s")
    lines.append("")
    lines += ["## What varies", ""]
    for p, values in spec.grid.items():
        lines.append(f"- grid `{p}`: {', '.join(json.dumps(v) for v in values)}")
    if spec.monte_carlo is not None:
        mc = spec.monte_carlo
        lines.append(f"- Monte Carlo: n = {mc.n}, seed = {mc.seed}, TC-noise seeds {mc.seeds.replace('_', ' ')}"
                     + (" (crossed with the grid: each grid point runs every sample)" if spec.grid else ""))
        for p, d in mc.fields.items():
            args = ", ".join(f"{k} = {v}" for k, v in d.model_dump().items() if k != "dist" and v is not None)
            lines.append(f"  - `{p}` ~ {d.dist}({args})")
    lines.append("")
    lines += ["## Best case per metric", "",
              "Errors relative to the setpoint; smaller is better. Design points (the grid without `seed`) are "
              "ranked by their median over the seeds and samples; a best case is named only where it beats the "
              "next by more than the seed-to-seed spread (median over the points of max - min over their seeds).",
              "", "| metric | range of the points | seed spread | reading |", "|---|---|---|---|"]
    for b in best_cases(spec, rows):
        lines.append(f"| {b['metric']} | {_pct(b['min'])} - {_pct(b['max'])} | {_pct(b['spread'])} | "
                     f"{best_sentence(b)} |")
    lines.append("")
    if spec.monte_carlo is not None:
        lines += _percentile_section(spec, rows)
        lines += _sensitivity_section(spec, rows)
    failed = [r for r in rows if r["status"] == "failed"]
    if failed:
        lines += ["## Failed cases", "", "| case | parameters | error |", "|---|---|---|"]
        lines += [f"| `{r['key']}` | {_params(r['params'])} | {str(r['error']).replace('|', '/')} |" for r in failed]
        lines.append("")
    figures = summary.get("figures") or []
    if figures:
        lines += ["## Figures", ""]
        lines += [f"![{Path(f).stem}](figures/{Path(f).name})" for f in figures]
        lines.append("")
    lines += _timing_section(summary.get("timing") or {})
    write_atomic(path, "\n".join(lines).encode())
    return path


def _percentile_section(spec: StudySpec, rows: Sequence[Mapping[str, Any]]) -> list[str]:
    lines = ["## Percentiles over the Monte Carlo samples", ""]
    if not spec.grid:
        head = " | ".join(f"p{q}" for q in REPORT_PERCENTILES)
        lines += [f"| metric | {head} | mean | max |", "|---|" + "---|" * (len(REPORT_PERCENTILES) + 2)]
        for m, p in percentiles(rows).items():
            cells = [_pct(p[f"p{q}"]) for q in REPORT_PERCENTILES] + [_pct(p["mean"]), _pct(p["max"])]
            lines.append(f"| {m} | " + " | ".join(cells) + " |")
        return [*lines, ""]
    by_point: dict[str, list[Mapping[str, Any]]] = defaultdict(list)
    for r in rows:
        by_point[_params({p: r["params"][p] for p in spec.grid})].append(r)
    stats = {k: percentiles(v) for k, v in by_point.items()}
    metrics = [m for m in METRIC_KEYS if any(m in s for s in stats.values())]
    lines += ["Each cell: p50 (p95).", "", "| grid point | " + " | ".join(metrics) + " |",
              "|---|" + "---|" * len(metrics)]
    for k, s in stats.items():
        cells = [f"{_pct(s[m]['p50'])} ({_pct(s[m]['p95'])})" if m in s else "n/a" for m in metrics]
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def sensitivities(spec: StudySpec, rows: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    """Spearman rank correlation of each metric with each numeric Monte Carlo field, over the finished
    cases (with a grid: the mean of the correlations within each grid point)."""
    from scipy.stats import spearmanr

    if spec.monte_carlo is None:
        return {}
    done = _finished(rows)
    groups: dict[str, list[Mapping[str, Any]]] = defaultdict(list)
    for r in done:
        groups[json.dumps({p: r["params"][p] for p in spec.grid}, sort_keys=True)].append(r)
    fields = [f for f in spec.monte_carlo.fields
              if all(isinstance(r["params"].get(f), (int, float)) and not isinstance(r["params"].get(f), bool)
                     for r in done)]
    out: dict[str, dict[str, float]] = {}
    for m in _metric_keys(done):
        for f in fields:
            rhos = []
            for members in groups.values():
                pairs = [(r["params"][f], r["metrics"][m]) for r in members if r["metrics"].get(m) is not None]
                if len(pairs) >= 3 and len({p[0] for p in pairs}) > 1 and len({p[1] for p in pairs}) > 1:
                    rhos.append(float(spearmanr([p[0] for p in pairs], [p[1] for p in pairs]).statistic))
            if rhos:
                out.setdefault(m, {})[f] = float(np.mean(rhos))
    return out


def _sensitivity_section(spec: StudySpec, rows: Sequence[Mapping[str, Any]]) -> list[str]:
    table = sensitivities(spec, rows)
    fields = sorted({f for v in table.values() for f in v}, key=list(spec.monte_carlo.fields).index) \
        if spec.monte_carlo else []
    if not fields:
        return []
    lines = ["## Which model error drives which metric", "",
             "Spearman rank correlation over the samples (+1: the metric grows with the field; |rho| < 0.25 is "
             "hardly distinguishable from none at n = 60)" + (", mean over the grid points" if spec.grid else "")
             + ".", "", "| metric | " + " | ".join(f"`{f}`" for f in fields) + " |", "|---|" + "---|" * len(fields)]
    for m, row in table.items():
        lines.append(f"| {m} | " + " | ".join(f"{row[f]:+.2f}" if f in row else "n/a" for f in fields) + " |")
    return [*lines, ""]


def _timing_section(t: Mapping[str, Any]) -> list[str]:
    if not t.get("cases"):
        return []

    def s(v: Any, fmt: str = "{:.3f} s") -> str:
        return "n/a" if v is None else fmt.format(v)

    return ["## Timing", "",
            f"- case (loop build with the feedforward OCP, samples, metrics): median {s(t['case_s'])}",
            f"- hand-off between cases on a worker: median {s(t['gap_s'])}, mean {s(t['gap_s_mean'])}",
            f"- set-up per case with the furnace cached: median {s(t['setup_s'])}; first case of a worker "
            f"(loads the radiation tables): median {s(t['load_s'])}",
            f"- per-case overhead (hand-off + cached set-up): {s(t['overhead_fraction'], '{:.2%}')} of a case",
            f"- this invocation: {t['computed']} cases on {t['workers']} workers in {t['wall_s']:.1f} s, worker "
            f"efficiency {s(t['efficiency'], '{:.0%}')} (busy / (wall x workers), cluster start-up included)", ""]

