"""Figures of an open-loop plant run (``furnace-twin simulate``): PNG, matplotlib Agg.

- :func:`plot_field`: the plant's temperature field at one time, with the fillet outline
  and the thermocouple positions, and below it the fillet's deviation from its mean;
- :func:`plot_tc_traces`: the four TC readings, the fillet mean and the group powers
  (and eta when the specimen oscillates).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
from numpy.typing import ArrayLike  # noqa: E402

TC_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
GROUP_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")


def plot_field(
    path: Path,
    field: ArrayLike,
    x: ArrayLike,
    y: ArrayLike,
    length: float,
    width: float,
    fillet: tuple[float, float, float, float],
    tc_positions: Sequence[tuple[float, float]],
    title: str = "",
) -> Path:
    """Field (N_y, N_x) in K as cells over the plate; x (length, downwards in the furnace) horizontal.

    Parameters
    ----------
    field : (N_y, N_x) K, rows = y
    x, y : cell centres (m)
    length, width : L_s, W_s (m)
    fillet : (x0, x1, y0, y1) m
    tc_positions : absolute (x, y) m of TC1..TC4
    """
    F = np.asarray(field, float)
    xc, yc = np.asarray(x, float), np.asarray(y, float)
    xe = np.linspace(0.0, length, len(xc) + 1) * 1e3
    ye = np.linspace(0.0, width, len(yc) + 1) * 1e3
    x0, x1, y0, y1 = fillet
    fig, axes = plt.subplots(2, 1, figsize=(9.0, 9.0), constrained_layout=True)
    # top: the whole plate in K; bottom: the fillet relative to its mean (inhomogeneity)
    mesh = axes[0].pcolormesh(xe, ye, F, cmap="inferno", shading="flat")
    fig.colorbar(mesh, ax=axes[0], shrink=0.9).set_label("T (K)")
    inside = (xc[None, :] > x0) & (xc[None, :] < x1) & (yc[:, None] > y0) & (yc[:, None] < y1)
    mean = float(F[inside].mean()) if inside.any() else float(F.mean())
    dev = np.where(inside, F - mean, np.nan)
    lim = max(float(np.nanmax(np.abs(dev))) if inside.any() else 1.0, 0.5)
    mesh = axes[1].pcolormesh(xe, ye, dev, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="flat")
    fig.colorbar(mesh, ax=axes[1], shrink=0.9).set_label(f"T - fillet mean {mean:.0f} K (K)")
    for ax in axes:
        ax.add_patch(
            Rectangle(
                (x0 * 1e3, y0 * 1e3),
                (x1 - x0) * 1e3,
                (y1 - y0) * 1e3,
                fill=False,
                edgecolor="0.5" if ax is axes[1] else "white",
                linestyle="--",
                linewidth=1.5,
                label="fillet",
            )
        )
        for i, (px, py) in enumerate(tc_positions):
            ax.plot(px * 1e3, py * 1e3, "o", ms=9, mfc=TC_COLOURS[i % 4], mec="white", mew=1.5)
            ax.annotate(
                f"TC{i + 1}",
                (px * 1e3, py * 1e3),
                xytext=(6, 6),
                textcoords="offset points",
                color="white" if ax is axes[0] else "black",
                fontsize=10,
                fontweight="bold",
            )
        ax.set_xlim(0, length * 1e3)
        ax.set_ylim(0, width * 1e3)
        ax.set_xlabel("x (mm), along the length, 0 = upper holder")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
        ax.legend(loc="upper right", fontsize=8, framealpha=0.6)
    axes[0].set_title(title or f"plant field: min {F.min():.0f} K, max {F.max():.0f} K")
    axes[1].set_title("fillet: deviation from its mean")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_tc_traces(
    path: Path,
    t: ArrayLike,
    tc: ArrayLike,
    fillet_mean: ArrayLike,
    u: ArrayLike,
    eta: ArrayLike,
    group_names: Sequence[str],
    title: str = "",
) -> Path:
    """TC readings (n, 4) with the fillet mean, group powers (n, 6) and eta (n,) over t (n,)."""
    tt = np.asarray(t, float)
    e = np.asarray(eta, float)
    oscillating = bool(np.any(np.abs(e) > 1e-12))
    rows = 3 if oscillating else 2
    ratios = [3, 1.4, 1][:rows]
    fig, axes = plt.subplots(
        rows,
        1,
        figsize=(10, 2.6 * sum(ratios) / 1.6),
        sharex=True,
        constrained_layout=True,
        gridspec_kw={"height_ratios": ratios},
    )
    ax = axes[0]
    Y = np.asarray(tc, float)
    for i in range(Y.shape[1]):
        ax.plot(tt, Y[:, i], color=TC_COLOURS[i % 4], lw=1.0, label=f"TC{i + 1}")
    ax.plot(tt, np.asarray(fillet_mean, float), color="k", lw=1.5, ls="--", label="fillet mean (true)")
    ax.set_ylabel("T (K)")
    ax.legend(ncol=5, fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    ax.set_title(title or "open-loop plant run")
    U = np.asarray(u, float)
    for i in range(U.shape[1]):
        axes[1].step(tt, 100 * U[:, i], where="post", color=GROUP_COLOURS[i % 6], label=group_names[i])
    axes[1].set_ylabel("u (% of u_max)")
    axes[1].set_ylim(-5, 105)
    axes[1].legend(ncol=6, fontsize=8, loc="lower right")
    axes[1].grid(alpha=0.3)
    if oscillating:
        axes[2].plot(tt, 1e3 * e, color="0.3")
        axes[2].set_ylabel("eta (mm)")
        axes[2].grid(alpha=0.3)
    axes[-1].set_xlabel("t (s)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
