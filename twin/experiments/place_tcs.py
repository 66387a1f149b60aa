"""``furnace-twin place-tcs``: rank thermocouple positions by what they tell about the field (Remark 3).

The nominal run is the twin's own plan: the feedforward (OCP, eq. 20) for the reference 1100 K / 120 s over 240 s,
the model's trajectory under it (position-aware, eta(t) of the scenario's oscillation when ``--oscillate``), its
Jacobians (16) and the candidates' output rows phi(xi)^T (12b) at the FE nodes between the clamps and the
edges, plus the paper's positions.  :mod:`twin.estimation.placement` turns them into
window Gramians (30 s windows) and picks ``--count`` positions greedily by the information gain f(S) in nats about
the fillet's nodes
(prior p0 of ``[ekf]``, noise r0; candidates: the FE nodes, see :func:`candidate_grid`).  The output: the
positions best first, each with f of the set up to it, and the
paper's TC1-3 (0.25 / 0.5, 0.5 / 0.8, 0.75 / 0.5) as the baseline; with ``--map`` a PNG of f of each single
candidate with both sets marked.

Example
-------
>>> from twin.config import small_config
>>> r = rank_positions(small_config(), count=1, duration=4.0, t_E=2.0, setpoint=400.0, window_s=2.0, grid=(3, 3))
>>> len(r["positions"]), sorted(r["positions"][0]), r["baseline"]["paper"] > 0
(1, ['score', 'x', 'x_rel', 'y', 'y_rel'], True)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import FurnaceConfig
from twin.estimation.placement import greedy, information, window_gramians

PAPER_TC123 = ((0.25, 0.5), (0.5, 0.8), (0.75, 0.5))
CRITERION = ("information gain about the fillet's FE nodes, sum over 30 s windows of 1/2 (log det of their prior "
             "covariance p0 I - log det of their posterior block of (I / p0 + W)^-1) in nats, W the observability "
             "Gramian of the reduced model along the nominal run (plan 1100 K / 120 s, 240 s)")


def candidate_grid(cfg: FurnaceConfig, grid: tuple[int, int] | None = None) -> np.ndarray:
    """Relative candidate positions (x / L_s, y / W_s), row by row in y: the FE nodes off the plate's edges and
    clamps (0.05 < x < 0.95, 0 < y < 1), or a regular ``grid`` (nx, ny) over 0.15..0.85 x 0.1..0.9.

    On the nodes every candidate's output row phi(xi)^T is a unit vector; between nodes a TC reads a weighted mean
    of neighbouring nodes, which the criterion (an independent prior per node) undervalues: on a regular grid the
    greedy choice lands on node lines for that reason alone."""
    if grid is not None:
        xs, ys = np.linspace(0.15, 0.85, grid[0]), np.linspace(0.1, 0.9, grid[1])
    else:
        x, y = np.asarray(cfg.fe.x_nodes, float), np.asarray(cfg.fe.y_nodes, float)
        xs, ys = x[(x > 0.05) & (x < 0.95)], y[(y > 0.0) & (y < 1.0)]
    return np.array([(xv, yv) for yv in ys for xv in xs])


def fillet_nodes(cfg: FurnaceConfig) -> list[int]:
    """Indices k = i + n_x j of the FE nodes in the closed fillet (0.25..0.75 L_s x 0.2..0.8 W_s, relative)."""
    x, y = np.asarray(cfg.fe.x_nodes, float), np.asarray(cfg.fe.y_nodes, float)
    xi = np.flatnonzero((x >= 0.25 - 1e-9) & (x <= 0.75 + 1e-9))
    yj = np.flatnonzero((y >= 0.2 - 1e-9) & (y <= 0.8 + 1e-9))
    return [int(i + len(x) * j) for j in yj for i in xi]


def nominal_jacobians(cfg: FurnaceConfig, radiation: Any, oscillate: bool, setpoint: float, t_E: float,
                      duration: float) -> tuple[list[np.ndarray], Any]:
    """J_j along the model's run under its own feedforward plan (module docstring) and the model."""
    from twin.control.feedforward import solve_feedforward
    from twin.control.reference import reference_trajectory
    from twin.model.discrete import discrete_model
    from twin.model.parametric import ParametricModel
    from twin.model.tables import model_tables
    from twin.physics.motion import eta_function
    from twin.scenario import OscillationSpec, TransitionReference

    tables = model_tables(cfg, radiation)
    osc = OscillationSpec(enabled=True) if oscillate else None
    T0 = cfg.specimen.initial_temperature
    ref = reference_trajectory(TransitionReference(setpoint=setpoint, t_E=t_E), T0)
    plan = solve_feedforward(discrete_model(cfg, radiation, osc, tables=tables), np.full(tables.n, T0), 0.0, ref,
                             cfg, horizon=duration, best_effort=True)
    model = ParametricModel(tables, osc, motion="position_aware")
    eta = eta_function(osc) if osc is not None else (lambda t: 0.0)
    theta, out = np.full(tables.n, T0), []
    t_s = cfg.sampling.t_s
    for j in range(plan.n_steps):
        u, e = plan.u_ff[j], float(eta(j * t_s))
        out.append(np.asarray(model.jac_theta(theta, u, e), float))
        theta = model.step(theta, u, e)
    return out, model


def rank_positions(cfg: FurnaceConfig, *, count: int = 3, oscillate: bool = False, setpoint: float = 1100.0,
                   t_E: float = 120.0, duration: float = 240.0, window_s: float = 30.0,
                   grid: tuple[int, int] | None = None, radiation: Any = None) -> dict[str, Any]:
    """The ranking of the module docstring as the JSON of ``place-tcs --json`` (plus ``"map"``: every
    candidate's relative position and single-TC score, for the figure)."""
    from twin.radiation import radiation_model

    rad = radiation if radiation is not None else radiation_model(cfg)
    jac, model = nominal_jacobians(cfg, rad, oscillate, setpoint, t_E, duration)
    rel = np.vstack([candidate_grid(cfg, grid), np.array(PAPER_TC123)])
    s = cfg.specimen
    absolute = rel * np.array([s.length, s.width])
    rows = model.fe.phi(absolute)
    window = max(1, int(round(window_s / cfg.sampling.t_s)))
    W = window_gramians(jac, rows, window, cfg.ekf.r0).astype(np.float32)
    p0 = cfg.ekf.p0
    focus = fillet_nodes(cfg)
    chosen, values = greedy(W, count, p0, focus)
    n_paper = len(PAPER_TC123)
    paper = list(range(len(rel) - n_paper, len(rel)))
    singles = [information(W, [c], p0, focus) for c in range(len(rel) - n_paper)]
    return {
        "positions": [{"x": float(absolute[c, 0]), "y": float(absolute[c, 1]), "x_rel": float(rel[c, 0]),
                       "y_rel": float(rel[c, 1]), "score": float(v)} for c, v in zip(chosen, values, strict=True)],
        "criterion": CRITERION if (setpoint, t_E, duration, window_s) == (1100.0, 120.0, 240.0, 30.0) else
        f"information gain (nats), {window_s:g} s windows, plan {setpoint:g} K / {t_E:g} s over {duration:g} s",
        "oscillate": oscillate,
        "baseline": {"paper": float(information(W, paper[:count] if count < n_paper else paper, p0, focus)),
                     "paper_positions": [list(p) for p in PAPER_TC123]},
        "map": {"rel": rel[:-n_paper].tolist(), "score": singles},
    }


def map_figure(result: dict[str, Any], cfg: FurnaceConfig, path: Path, title: str) -> None:
    """PNG: each candidate's single-TC information over the specimen, the recommended and the paper's TCs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from twin.physics.fillet import fillet_box

    s = cfg.specimen  # (the map: each candidate alone, about the fillet's nodes)
    rel = np.asarray(result["map"]["rel"])
    xs, ys = np.unique(rel[:, 0]), np.unique(rel[:, 1])
    Z = np.asarray(result["map"]["score"]).reshape(len(ys), len(xs))
    fig, ax = plt.subplots(figsize=(7.0, 4.0), dpi=120)
    pc = ax.pcolormesh(xs * s.length, ys * s.width, Z, shading="nearest", cmap="viridis")
    fig.colorbar(pc, ax=ax, label="information of one TC there (nats)")
    x0, x1, y0, y1 = fillet_box(s.length, s.width)
    ax.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", color="w", lw=1.2))
    for k, p in enumerate(result["positions"]):
        ax.plot(p["x"], p["y"], "o", ms=11, mfc="none", mec="#ff4fc8", mew=2.2)
        ax.annotate(f"#{k + 1}", (p["x"], p["y"]), xytext=(7, 7), textcoords="offset points", color="#ff4fc8",
                    fontsize=10, fontweight="bold")
    paper = np.array(result["baseline"]["paper_positions"]) * np.array([s.length, s.width])
    ax.plot(paper[:, 0], paper[:, 1], "s", ms=8, mfc="none", mec="w", mew=1.8, label="paper TC1-3")
    ax.plot([], [], "o", mfc="none", mec="#ff4fc8", mew=2.2, label="recommended (greedy)")
    ax.set_xlim(0, s.length)
    ax.set_ylim(0, s.width)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m), along the specimen length")
    ax.set_ylabel("y (m)")
    best = result["positions"][-1]["score"] if result["positions"] else float("nan")
    ax.set_title(f"{title}: recommended {best:.0f} nats, paper {result['baseline']['paper']:.0f} nats", fontsize=10)
    ax.legend(loc="lower right", fontsize=8, framealpha=0.8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def add_arguments(p: Any) -> None:
    p.add_argument("--count", type=int, default=3, help="how many TC positions to choose (default 3)")
    p.add_argument("--oscillate", action="store_true", help="the nominal run oscillates (position-aware model)")
    p.add_argument("--json", action="store_true", help="print the ranking as JSON")
    p.add_argument("--map", default=None, metavar="PNG", help="also draw the map to this PNG file")


def place_tcs_command(cfg: FurnaceConfig, args: Any) -> int:
    if not 1 <= args.count <= 6:
        sys.stderr.write("furnace-twin place-tcs: --count must be between 1 and 6\n")
        return 2
    result = rank_positions(cfg, count=args.count, oscillate=args.oscillate)
    if args.map:
        map_figure(result, cfg, Path(args.map), "oscillating" if args.oscillate else "fixed")
    out = {k: v for k, v in result.items() if k != "map"}
    if args.json:
        sys.stdout.write(json.dumps(out) + "\n")
        return 0
    lines = [f"criterion: {out['criterion']}", "rank  x (m)   y (m)   x/L_s  y/W_s  f of the set so far (nats)"]
    for k, p in enumerate(out["positions"]):
        lines.append(f"{k + 1:>4}  {p['x']:.4f}  {p['y']:.4f}  {p['x_rel']:.3f}  {p['y_rel']:.3f}  {p['score']:.1f}")
    lines.append(f"paper TC1-3 (0.25/0.5, 0.5/0.8, 0.75/0.5): {out['baseline']['paper']:.1f}")
    sys.stdout.write("\n".join(lines) + "\n")
    return 0
