"""Figures of a study (PNG, matplotlib Agg), from its results table.

- a grid with two or more design fields (grid fields but ``seed``, a replicate): one figure per metric
  (:func:`plot_heatmap`), one map over the first two design fields per value of the third, all on one colour
  scale, the median over the other fields, the seeds and the Monte Carlo samples;
- a grid with one design field: each metric against it, with the 5-95 % band of the samples (:func:`plot_lines`);
- Monte Carlo: the distribution of every metric with its 5th, 50th and 95th percentile
  (:func:`plot_distributions`; box plots per grid point when crossed with a grid).

Metrics are shown in % of the setpoint T_ref(t_E), like the paper.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from twin.runs.metrics import METRIC_KEYS, METRIC_WORDS  # noqa: E402
from twin.studies.cases import Case  # noqa: E402
from twin.studies.report import best_cases, design_fields  # noqa: E402
from twin.studies.spec import StudySpec  # noqa: E402

PERCENTILES = (5, 50, 95)
#: more grid points than this and the per-point box plots are left out (unreadable)
MAX_BOXES = 40


def metric_values(cols: dict[str, list[Any]], metric: str) -> np.ndarray:
    """A metric column in % of the setpoint (NaN where a case failed or is pending)."""
    return 100.0 * np.array([np.nan if v is None else v for v in cols[metric]], float)


def metric_name(key: str) -> str:
    """A metric's name in the glossary's words (``METRIC_WORDS``, as the dashboard shows it), else its key."""
    return METRIC_WORDS[key][0] if key in METRIC_WORDS else key


def label(v: Any) -> str:
    return f"{v:g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else json.dumps(v)


def present_metrics(cols: dict[str, list[Any]]) -> list[str]:
    return [m for m in METRIC_KEYS if m in cols and np.isfinite(metric_values(cols, m)).any()]


def plot_study(spec: StudySpec, cases: Sequence[Case], table: Any, folder: Path) -> list[Path]:
    """All figures the study calls for (``table`` in the order of ``cases``); returns their paths."""
    cols = table.to_pydict()
    cols.update({p: [c.params.get(p) for c in cases] for p in spec.varied()})  # values as written, not as stored
    metrics = present_metrics(cols)
    if not metrics:
        return []
    folder.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    rows = [{"key": c.key, "params": c.params, "status": "done", "metrics": {m: cols[m][i] for m in metrics}}
            for i, c in enumerate(cases)]
    grid = design_fields(spec)
    if len(grid) >= 2:
        for m in metrics:
            paths.append(plot_heatmap(spec, cols, m, grid[0], grid[1], folder / f"heatmap_{m}.png",
                                      facet=grid[2] if len(grid) > 2 else None, rows=rows))
    elif len(grid) == 1:
        paths.append(plot_lines(spec, cols, metrics, grid[0], folder / "metrics_vs_grid.png", rows=rows))
    if spec.monte_carlo is not None:
        n_points = len(set(cols["grid_point"]))
        if not grid or n_points <= MAX_BOXES:
            paths.append(plot_distributions(spec, cols, metrics, folder / "distributions.png"))
    return paths


def _cells(cols: dict[str, list[Any]], path: str) -> list[str]:
    return [label(v) for v in cols[path]]


def colour_range(lo: float, hi: float, spread: float | None) -> tuple[float, float]:
    """The colour scale of a metric's maps (% values): its points' min-max, widened about its middle to at
    least the seed-to-seed spread, so that two cells closer than the noise never look like opposite ends."""
    span = max(hi - lo, spread or 0.0, 1e-9)
    mid = 0.5 * (lo + hi)
    return mid - span / 2, mid + span / 2


def plot_heatmap(spec: StudySpec, cols: dict[str, list[Any]], metric: str, x_path: str, y_path: str,
                 path: Path, facet: str | None = None, rows: list[dict[str, Any]] | None = None) -> Path:
    """Median of ``metric`` over each (x, y) cell of the grid, one map per value of ``facet`` (when given), all
    maps on one colour scale (:func:`colour_range`); the title states the range and the seed-to-seed spread, and
    the best cell is outlined only where the study names one (``twin.studies.report.best_cases``)."""
    xs = [label(v) for v in spec.grid[x_path]]
    ys = [label(v) for v in spec.grid[y_path]]
    fs = [label(v) for v in spec.grid[facet]] if facet else [None]
    values = metric_values(cols, metric)
    cx, cy = _cells(cols, x_path), _cells(cols, y_path)
    cf = _cells(cols, facet) if facet else [None] * len(cx)
    Z = np.full((len(fs), len(ys), len(xs)), np.nan)
    counts = np.zeros_like(Z, int)
    for k, fv in enumerate(fs):
        for i, yv in enumerate(ys):
            for j, xv in enumerate(xs):
                sel = np.array([a == xv and b == yv and c == fv for a, b, c in zip(cx, cy, cf, strict=True)])
                v = values[sel]
                v = v[np.isfinite(v)]
                counts[k, i, j] = v.size
                if v.size:
                    Z[k, i, j] = float(np.median(v))
    best = next((b for b in best_cases(spec, rows or []) if b["metric"] == metric), None)
    spread = 100.0 * best["spread"] if best and best["spread"] is not None else None
    finite = Z[np.isfinite(Z)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    vmin, vmax = colour_range(lo, hi, spread)
    fig, axes = plt.subplots(1, len(fs), figsize=(len(fs) * (1.2 * len(xs) + 1.6) + 1.6, 0.8 * len(ys) + 2.6),
                             constrained_layout=True, squeeze=False)
    im = None
    for k, ax in enumerate(axes[0]):
        im = ax.imshow(Z[k], origin="lower", cmap="viridis", aspect="auto", vmin=vmin, vmax=vmax)
        ax.set_xticks(range(len(xs)), xs)
        ax.set_yticks(range(len(ys)), ys)
        ax.set_xlabel(x_path)
        if k == 0:
            ax.set_ylabel(y_path)
        if facet:
            ax.set_title(f"{facet} = {fs[k]}", fontsize=9)
        for i in range(len(ys)):
            for j in range(len(xs)):
                z = Z[k, i, j]
                text = "failed" if not np.isfinite(z) else f"{z:.2f}"
                ax.text(j, i, text, ha="center", va="center", fontsize=9,
                        color="black" if np.isfinite(z) and z > 0.5 * (vmin + vmax) else "white")
        if best and best["decided"]:
            p = best["params"]
            if label(p[x_path]) in xs and label(p[y_path]) in ys and (not facet or label(p[facet]) == fs[k]):
                bj, bi = xs.index(label(p[x_path])), ys.index(label(p[y_path]))
                ax.add_patch(Rectangle((bj - 0.5, bi - 0.5), 1, 1, fill=False, edgecolor="red", linewidth=2.5))
    assert im is not None  # one map at least
    fig.colorbar(im, ax=axes[0].tolist(), label=f"{metric_name(metric)} (% of setpoint)")
    title = f"{spec.name or 'study'}: {metric_name(metric)}"
    if counts.max() > 1:
        title += f", median of {counts.max()} cases per cell"
    spread_text = f"seed-to-seed spread {spread:.2f} %" if spread is not None else "seed spread unknown (one seed)"
    verdict = "red: best, beyond the spread" if best and best["decided"] else "no cell better than the spread"
    title += f"\nrange {lo:.2f} - {hi:.2f} %, {spread_text}; {verdict}"
    fig.suptitle(title, fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_lines(spec: StudySpec, cols: dict[str, list[Any]], metrics: Sequence[str], x_path: str,
               path: Path, rows: list[dict[str, Any]] | None = None) -> Path:
    """Each metric against the one grid field: median, and the 5-95 % band when there are samples."""
    xs = spec.grid[x_path]
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xs)
    pos = np.asarray(xs, float) if numeric else np.arange(len(xs), dtype=float)
    cells = _cells(cols, x_path)
    n = len(metrics)
    ncol = min(n, 3)
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.0 * nrow), constrained_layout=True, squeeze=False)
    for ax, m in zip(axes.ravel(), metrics, strict=False):
        v = metric_values(cols, m)
        per_x = [v[[c == label(x) for c in cells]] for x in xs]
        per_x = [r[np.isfinite(r)] for r in per_x]
        med = np.array([np.median(r) if r.size else np.nan for r in per_x])
        ax.plot(pos, med, "o-")
        best = next((b for b in best_cases(spec, rows or []) if b["metric"] == m), None)
        spread = 100.0 * best["spread"] if best and best["spread"] is not None else None
        if np.isfinite(med).any():  # like the maps' colour scale: no axis narrower than the seed spread
            y0, y1 = colour_range(float(np.nanmin(med)), float(np.nanmax(med)), spread)
            ax.set_ylim(y0 - 0.1 * (y1 - y0), y1 + 0.1 * (y1 - y0))
        ax.ticklabel_format(axis="y", useOffset=False)
        if spread is not None:
            ax.set_xlabel(f"{x_path}   (seed spread {spread:.2f} %)")
        if spec.monte_carlo is not None:
            lo = np.array([np.percentile(r, 5) if r.size else np.nan for r in per_x])
            hi = np.array([np.percentile(r, 95) if r.size else np.nan for r in per_x])
            ax.fill_between(pos, lo, hi, alpha=0.25, label="5-95 %")
        ax.set_title(metric_name(m), fontsize=9)
        ax.set_ylabel("% of setpoint")
        if spread is None:
            ax.set_xlabel(x_path)
        if not numeric:
            ax.set_xticks(pos, [label(x) for x in xs])
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    fig.suptitle(spec.name or "study")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_distributions(spec: StudySpec, cols: dict[str, list[Any]], metrics: Sequence[str], path: Path) -> Path:
    """Histograms with the 5th / 50th / 95th percentiles; with a grid, box plots (whiskers 5-95 %) per point."""
    n = len(metrics)
    ncol = min(n, 3)
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.4 * ncol, 3.0 * nrow), constrained_layout=True, squeeze=False)
    points = sorted({p for p in cols["grid_point"] if p is not None})
    for ax, m in zip(axes.ravel(), metrics, strict=False):
        v = metric_values(cols, m)
        if points:
            data = [v[[gp == p for gp in cols["grid_point"]]] for p in points]
            data = [d[np.isfinite(d)] for d in data]
            ax.boxplot(data, whis=(5, 95), showfliers=True, flierprops={"markersize": 2})
            ax.set_xlabel("grid point")
        else:
            d = v[np.isfinite(v)]
            ax.hist(d, bins=min(30, max(5, d.size // 3)), color="#7a9cc6", edgecolor="white")
            for q, style in zip(PERCENTILES, (":", "-", ":"), strict=True):
                x = float(np.percentile(d, q))
                ax.axvline(x, color="#c0392b", linestyle=style, linewidth=1.4)
                ax.text(x, ax.get_ylim()[1] * 0.97, f" p{q} {x:.2f}", rotation=90, va="top", ha="right", fontsize=7)
            ax.set_xlabel("% of setpoint")
            ax.set_ylabel("cases")
        ax.set_title(metric_name(m), fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    mc = spec.monte_carlo
    fig.suptitle(f"{spec.name or 'study'}: Monte Carlo, n = {mc.n if mc else 0} (lines: p5, p50, p95)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
