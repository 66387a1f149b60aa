"""Figures in the style of the paper's Figs. 4-9, from stored time series (PNG, matplotlib Agg).

- :func:`plot_run_signals`: Fig. 4 / Fig. 6 style: (A) relative mean error, (B) TC1-3 errors,
  (C) TC4 error, (D) inhomogeneity T_sup, (E) horizontal and (F) vertical group powers,
  and eta for an oscillating run.
- :func:`plot_run_field`: Fig. 5 / Fig. 8 style: estimated 2D field relative to the setpoint at
  1.5 t_E, profiles along x and y through the TC positions at 0.5 t_E and 1.5 t_E.
- :func:`plot_homogeneity_comparison`: Fig. 9 style: T_sup fixed vs oscillating per TC4 position.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.layout_engine import ConstrainedLayoutEngine  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from twin.physics.fillet import FILLET_X, FILLET_Y, Fillet  # noqa: E402

TC_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
GROUP_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")


def _pct(values: Any, scale: float) -> Any:
    return 100.0 * np.asarray(values, float) / scale


def _sup_series(ts: Mapping[str, Any], key: str = "field_hat") -> tuple[Any, Any]:
    tf = np.asarray(ts["t_field"], float)
    fillet = Fillet.on_grid(np.asarray(ts["x"]), np.asarray(ts["y"]), float(ts["L_s"]), float(ts["W_s"]))
    ref = np.interp(tf, np.asarray(ts["t"], float), np.asarray(ts["T_ref"], float))
    return tf, fillet.sup(np.asarray(ts[key], float), ref)


def _group_names(ts: Mapping[str, Any], n: int) -> list[str]:
    names = ts.get("group_names")
    return [str(v) for v in names] if names is not None else [f"group {i + 1}" for i in range(n)]


def plot_run_signals(ts: Mapping[str, Any], path: Path, title: str = "") -> Path:
    """Fig. 4 (fixed) / Fig. 6 (oscillating) layout for one run."""
    t = np.asarray(ts["t"], float)
    scale = float(ts["setpoint"])
    t_E = float(ts["t_E"])
    eta = np.asarray(ts["eta"], float)
    oscillating = bool(np.any(np.abs(eta) > 1e-9))
    u, u_ff = np.asarray(ts["u"], float), np.asarray(ts["u_ff"], float)
    names = _group_names(ts, u.shape[1])
    horizontal = [i for i, n in enumerate(names) if n.endswith("h")] or list(range(u.shape[1]))
    vertical = [i for i, n in enumerate(names) if n.endswith("v")]
    rows = 4 if oscillating else 3
    fig, axes = plt.subplots(rows, 2, figsize=(12, 3.0 * rows), sharex=True, constrained_layout=True)
    ax = axes.ravel()
    ax[0].plot(t, _pct(np.asarray(ts["T_mean_hat"]) - np.asarray(ts["T_ref"]), scale), color="k")
    ax[0].set_ylabel("e / T_ref(t_E) (%)")
    ax[0].set_title("(A) mean temperature error (estimate)")
    tc, tc_hat = np.asarray(ts["tc"], float), np.asarray(ts["tc_hat"], float)
    for i in range(3):
        ax[1].plot(t, _pct(tc[:, i] - tc_hat[:, i], scale), color=TC_COLOURS[i], lw=0.8, label=f"TC{i + 1}")
    ax[1].set_title("(B) local errors TC1-3 (used by the EKF)")
    ax[1].set_ylabel("e_TCi / T_ref(t_E) (%)")
    ax[1].legend(loc="upper right", ncol=3, fontsize=8)
    ax[2].plot(t, _pct(tc[:, 3] - tc_hat[:, 3], scale), color=TC_COLOURS[3], lw=0.8)
    ax[2].set_title("(C) validation error TC4")
    ax[2].set_ylabel("e_TC4 / T_ref(t_E) (%)")
    tf, sup = _sup_series(ts)
    ax[3].plot(tf, _pct(sup, scale), color="k", label="estimate")
    if "field_true" in ts:
        _, sup_true = _sup_series(ts, "field_true")
        ax[3].plot(tf, _pct(sup_true, scale), color="0.6", ls="--", label="plant (truth)")
    ax[3].set_title("(D) inhomogeneity T_sup")
    ax[3].set_ylabel("T_sup / T_ref(t_E) (%)")
    ax[3].legend(loc="upper right", fontsize=8)
    for k, (idx, label) in enumerate(((horizontal, "(E) horizontal groups"), (vertical, "(F) vertical groups"))):
        a = ax[4 + k]
        for i in idx:
            a.plot(t, 100 * u[:, i], color=GROUP_COLOURS[i % 6], label=names[i])
            a.plot(t, 100 * u_ff[:, i], color=GROUP_COLOURS[i % 6], ls=":", lw=0.8)
        a.set_title(f"{label}: u (solid), u_ff (dotted)")
        a.set_ylabel("u / u_max (%)")
        a.set_ylim(-3, 103)
        if idx:
            a.legend(loc="lower right", ncol=len(idx), fontsize=8)
    if oscillating:
        ax[6].plot(t, 1000 * eta, color="k")
        ax[6].set_title("specimen position")
        ax[6].set_ylabel("eta (mm)")
        ax[7].axis("off")
    for a in ax:
        if a.has_data():
            a.axvline(t_E, color="0.7", lw=0.8)
            a.grid(alpha=0.3)
    for a in axes[-1]:
        a.set_xlabel("t (s)")
    fig.suptitle(title or ("oscillating specimen" if oscillating else "fixed specimen"))
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _nearest(t: Any, value: float) -> int:
    return int(np.argmin(np.abs(np.asarray(t) - value)))


def plot_run_field(ts: Mapping[str, Any], path: Path, title: str = "") -> Path:
    """Fig. 5 / Fig. 8 layout: field at 1.5 t_E and profiles through the TCs at 0.5 and 1.5 t_E."""
    x, y = np.asarray(ts["x"], float), np.asarray(ts["y"], float)
    L_s, W_s, t_E, scale = float(ts["L_s"]), float(ts["W_s"]), float(ts["t_E"]), float(ts["setpoint"])
    tf = np.asarray(ts["t_field"], float)
    field = np.asarray(ts["field_hat"], float)
    tcp = np.asarray(ts["tc_positions"], float) if "tc_positions" in ts else None
    k15 = _nearest(tf, min(1.5 * t_E, tf[-1]))
    k05 = _nearest(tf, 0.5 * t_E)
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6), layout=ConstrainedLayoutEngine(wspace=0.06))
    rel = 100 * field[k15] / scale
    im = ax[0].imshow(
        rel, origin="lower", extent=(0, 100 * L_s, 0, 100 * W_s), cmap="turbo", aspect="equal", interpolation="bilinear"
    )
    fig.colorbar(im, ax=ax[0], label="T / T_ref(t_E) (%)", shrink=0.8, pad=0.02)
    ax[0].add_patch(
        Rectangle((100 * FILLET_X[0] * L_s, 100 * FILLET_Y[0] * W_s), 100 * (FILLET_X[1] - FILLET_X[0]) * L_s,
                  100 * (FILLET_Y[1] - FILLET_Y[0]) * W_s, fill=False, ec="w", lw=1.5, ls="--", label="fillet")
    )
    if tcp is not None:
        for i, (px, py) in enumerate(tcp):
            ax[0].plot(100 * px, 100 * py, "o" if i == 3 else "*", color="w", mec="k", ms=9)
            ax[0].annotate(f"TC{i + 1}", (100 * px, 100 * py), xytext=(4, 4), textcoords="offset points", color="w")
    ax[0].set_xlabel("x (cm)")
    ax[0].set_ylabel("y (cm)")
    ax[0].set_title(f"(A) estimated field at t = {tf[k15]:.0f} s")
    # profiles along x at y of TC1 (0.5 W_s) and along y at x of TC2 (0.5 L_s)
    jy = _nearest(y, 0.5 * W_s)
    ix = _nearest(x, 0.5 * L_s)
    for k, ls in ((k05, "--"), (k15, "-")):
        ax[1].plot(100 * x, 100 * field[k, jy, :] / scale, ls=ls, color="k", label=f"t = {tf[k]:.0f} s")
        ax[2].plot(100 * y, 100 * field[k, :, ix] / scale, ls=ls, color="k", label=f"t = {tf[k]:.0f} s")
    if tcp is not None:
        tcs = np.asarray(ts["tc"], float)
        t = np.asarray(ts["t"], float)
        for k in (k05, k15):
            j = _nearest(t, tf[k])
            for i, (px, py) in enumerate(tcp):
                marker = "o" if i == 3 else "*"
                if abs(py - y[jy]) <= 0.5 * (y[1] - y[0]) + 1e-9:
                    ax[1].plot(100 * px, 100 * tcs[j, i] / scale, marker, color=TC_COLOURS[i], ms=8)
                if abs(px - x[ix]) <= 0.5 * (x[1] - x[0]) + 1e-9:
                    ax[2].plot(100 * py, 100 * tcs[j, i] / scale, marker, color=TC_COLOURS[i], ms=8)
    ax[1].axvspan(25 * L_s, 75 * L_s, color="0.9", zorder=0)
    ax[2].axvspan(20 * W_s, 80 * W_s, color="0.9", zorder=0)
    ax[1].set_xlabel("x (cm)")
    ax[1].set_title(f"(B) profile along x at y = {100 * y[jy]:.1f} cm")
    ax[2].set_xlabel("y (cm)")
    ax[2].set_title(f"(C) profile along y at x = {100 * x[ix]:.1f} cm")
    for a in ax[1:]:
        a.set_ylabel("T / T_ref(t_E) (%)")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(title or "estimated temperature field (TC: * used by the EKF, o validation)")
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_run(ts: Mapping[str, Any], out: Path, title: str = "") -> list[Path]:
    """Both run figures into ``out``."""
    return [
        plot_run_signals(ts, out / "signals.png", title),
        plot_run_field(ts, out / "field.png", title),
    ]


def plot_homogeneity_comparison(
    pairs: Sequence[tuple[str, Mapping[str, Any], Mapping[str, Any]]], path: Path
) -> Path:
    """Fig. 9 layout: T_sup of the fixed and the oscillating run, one panel per TC4 position."""
    fig, axes = plt.subplots(len(pairs), 1, figsize=(9, 2.6 * len(pairs)), sharex=True, constrained_layout=True)
    axes = np.atleast_1d(axes)
    for a, (label, fixed, osc) in zip(axes, pairs, strict=True):
        for ts, name, colour in ((fixed, "fixed", "#1f77b4"), (osc, "oscillating", "#d62728")):
            tf, sup = _sup_series(ts)
            a.plot(tf, _pct(sup, float(ts["setpoint"])), color=colour, label=name)
        a.set_title(label)
        a.set_ylabel("T_sup / T_ref(t_E) (%)")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    axes[-1].set_xlabel("t (s)")
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
