"""Figures of a study (PNG, matplotlib Agg), from its results table.

- a grid with two or more fields: one heat map per metric over the first two grid fields
  (:func:`plot_heatmap`), the median over the other fields and the Monte Carlo samples;
- a grid with one field: each metric against it, with the 5-95 % band of the samples (:func:`plot_lines`);
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

from twin.runs.metrics import METRIC_KEYS  # noqa: E402
from twin.studies.cases import Case  # noqa: E402
from twin.studies.spec import StudySpec  # noqa: E402

PERCENTILES = (5, 50, 95)
#: more grid points than this and the per-point box plots are left out (unreadable)
MAX_BOXES = 40


def metric_values(cols: dict[str, list[Any]], metric: str) -> np.ndarray:
    """A metric column in % of the setpoint (NaN where a case failed or is pending)."""
    return 100.0 * np.array([np.nan if v is None else v for v in cols[metric]], float)


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
    grid = list(spec.grid)
    if len(grid) >= 2:
        for m in metrics:
            paths.append(plot_heatmap(spec, cols, m, grid[0], grid[1], folder / f"heatmap_{m}.png"))
    elif len(grid) == 1:
        paths.append(plot_lines(spec, cols, metrics, grid[0], folder / "metrics_vs_grid.png"))
    if spec.monte_carlo is not None:
        n_points = len(set(cols["grid_point"]))
        if not grid or n_points <= MAX_BOXES:
            paths.append(plot_distributions(spec, cols, metrics, folder / "distributions.png"))
    return paths


def _cells(cols: dict[str, list[Any]], path: str) -> list[str]:
    return [label(v) for v in cols[path]]


def plot_heatmap(spec: StudySpec, cols: dict[str, list[Any]], metric: str, x_path: str, y_path: str,
                 path: Path) -> Path:
    """Median of ``metric`` over each (x, y) cell of the grid; the best (smallest) cell is outlined."""
    xs = [label(v) for v in spec.grid[x_path]]
    ys = [label(v) for v in spec.grid[y_path]]
    values = metric_values(cols, metric)
    cx, cy = _cells(cols, x_path), _cells(cols, y_path)
    Z = np.full((len(ys), len(xs)), np.nan)
    counts = np.zeros_like(Z, int)
    for i, yv in enumerate(ys):
        for j, xv in enumerate(xs):
            sel = np.array([a == xv and b == yv for a, b in zip(cx, cy, strict=True)])
            v = values[sel]
            v = v[np.isfinite(v)]
            counts[i, j] = v.size
            if v.size:
                Z[i, j] = float(np.median(v))
    fig, ax = plt.subplots(figsize=(1.2 * len(xs) + 3.0, 0.8 * len(ys) + 2.2), constrained_layout=True)
    im = ax.imshow(Z, origin="lower", cmap="viridis", aspect="auto")
    fig.colorbar(im, ax=ax, label=f"{metric} (% of setpoint)")
    ax.set_xticks(range(len(xs)), xs)
    ax.set_yticks(range(len(ys)), ys)
    ax.set_xlabel(x_path)
    ax.set_ylabel(y_path)
    finite = Z[np.isfinite(Z)]
    mid = float(np.mean([finite.min(), finite.max()])) if finite.size else 0.0
    for i in range(len(ys)):
        for j in range(len(xs)):
            text = "failed" if not np.isfinite(Z[i, j]) else f"{Z[i, j]:.2f}"
            ax.text(j, i, text, ha="center", va="center", fontsize=9,
                    color="black" if np.isfinite(Z[i, j]) and Z[i, j] > mid else "white")
    if finite.size:
        bi, bj = (int(k) for k in np.unravel_index(np.nanargmin(Z), Z.shape))
        ax.add_patch(Rectangle((bj - 0.5, bi - 0.5), 1, 1, fill=False, edgecolor="red", linewidth=2.5))
    aggregated = counts.max() > 1
    title = f"{spec.name or 'study'}: {metric}"
    if aggregated:
        title += f"\nmedian of {counts.max()} cases per cell"
    ax.set_title(title, fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_lines(spec: StudySpec, cols: dict[str, list[Any]], metrics: Sequence[str], x_path: str,
               path: Path) -> Path:
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
        rows = [v[[c == label(x) for c in cells]] for x in xs]
        rows = [r[np.isfinite(r)] for r in rows]
        med = np.array([np.median(r) if r.size else np.nan for r in rows])
        ax.plot(pos, med, "o-")
        if spec.monte_carlo is not None:
            lo = np.array([np.percentile(r, 5) if r.size else np.nan for r in rows])
            hi = np.array([np.percentile(r, 95) if r.size else np.nan for r in rows])
            ax.fill_between(pos, lo, hi, alpha=0.25, label="5-95 %")
        ax.set_title(m, fontsize=9)
        ax.set_ylabel("% of setpoint")
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
        ax.set_title(m, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    mc = spec.monte_carlo
    fig.suptitle(f"{spec.name or 'study'}: Monte Carlo, n = {mc.n if mc else 0} (lines: p5, p50, p95)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
