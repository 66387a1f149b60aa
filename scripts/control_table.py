"""The before/after table of docs/control.md (issue 26): closed-loop runs against the honest truth, and the table.

    python scripts/control_table.py run --furnace default --variant paper --seeds 0 1 2 3 4 --out out/control
    python scripts/control_table.py run --furnace default --variant twin --seeds 0 1 2 3 4 --out out/control
    python scripts/control_table.py run --furnace default --variant twin --second-run --seeds 0 1 2 3 4 \
        --out out/control
    python scripts/control_table.py table --out docs/control_runs --write docs/control.md README.md

Each run: the paper's reference (1100 K in t_E = 120 s, 240 s), fixed specimen, TC4 at the centre, the simulated
furnace's own truth (``truth = "independent"``), one seed; the errors are recomputed from the true field of every
sample (``Snapshot.true_mean``), not from the twin's estimate.  Variants:

* ``paper``: the paper's controller (LQG, constant c_p in the plan, no reserve, no re-plan on the calibration), what
  the twin did before issue 26;
* ``twin``: the furnace file's ``[control]`` settings (the twin's defaults);
* ``lqg`` / ``mpc``: the furnace file's settings with that feedback.

``--second-run``: the run is planned with what the same seed's first run of the variant learnt (its
``calibration``, by the calibration memory's rule), like a second run of the same recipe on a server.

One JSON file per run in ``OUT/<furnace>/<variant>[-second]/seed_<k>.json``; ``table`` prints the markdown table
(worst over the seeds of each group).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

SETPOINT, T_E, DURATION = 1100.0, 120.0, 240.0
VARIANTS = {
    "paper": {"control.feedback": "lqg", "control.plan_heat_capacity": "constant", "control.feedforward_limit": 1.0,
              "control.position_feedforward": False, "calibration.controller_follows": False},
    "twin": {},
    "lqg": {"control.feedback": "lqg"},
    "mpc": {"control.feedback": "mpc"},
}
#: the table's columns: (key in a run's JSON, heading)
COLUMNS = (
    ("true_mean_error_transient_max", "true mean error, transient"),
    ("true_mean_error_transient_after_15s", "… after 15 s"),
    ("lamps_off_lead_max", "lamps-off bound, transient"),
    ("true_mean_error_steady_max", "true mean error, steady"),
    ("full_power_steady_max", "full power, steady (worst group)"),
    ("true_inhomogeneity_steady", "true T_sup, steady"),
    ("field_estimation_error_steady_max", "field estimation error, steady"),
)
#: issue 26's bounds per furnace (a cell above its bound is marked ✗): on `default` half the paper's 2 % in the
#: transient, 0.25 % steady, no group at full power over 10 % of the steady window; on `banded` the paper's 2 %
#: and 0.5 %
BOUNDS = {
    "default": {"true_mean_error_transient_max": 0.010, "true_mean_error_steady_max": 0.0025,
                "full_power_steady_max": 0.10},
    "banded": {"true_mean_error_transient_max": 0.020, "true_mean_error_steady_max": 0.005},
}


def _patient_plans(max_wall_s: float = 1800.0) -> None:
    """The first plan with IPOPT's wall-time limit raised from 120 s: on a machine shared by many jobs the OCP
    took longer than 120 s (the run then ends in error); the plan itself does not change."""
    import functools

    import twin.control.replan as replan
    from twin.control.feedforward import solve_feedforward

    replan.solve_feedforward = functools.partial(solve_feedforward, max_wall_s=max_wall_s)  # type: ignore[assignment]


#: how long (s) the furnace's free response is followed for the lamps-off bound: its lead on the paper's
#: reference ends by about 12 s, when the reference outruns the cold plate
LAMPS_OFF_S = 30.0


def lamps_off_bound(cfg: Any, scenario: Any, rad: Any, seconds: float = LAMPS_OFF_S) -> tuple[float, float]:
    """The reference's largest lead over the furnace left with every lamp off (fraction of the setpoint, >= 0), and
    when (s), over the first ``seconds``.

    The scenario's furnace (its own truth, seed and start) runs with u = 0; the reference starts where the run's
    does, at the mean of TC1-3's first reading (:class:`twin.runs.loop.ClosedLoop`).  Lamp power only adds heat
    (the radiative and conductive flows are monotone in it), so under any controller the true fillet mean is at
    least this free one, and ``max(free - T_ref)`` bounds the transient error from below: in the paper's heat-up
    the cold plate warms faster by itself (warm holders, inert gas, walls) than the reference starts."""
    from twin.control.reference import reference_trajectory
    from twin.furnace.simulated import SimulatedFurnace
    from twin.physics.fillet import Fillet

    furnace = SimulatedFurnace.for_scenario(cfg, scenario, rad)
    y0 = furnace.read(0.0).for_estimator()
    ref = reference_trajectory(scenario.reference, float(np.nanmean(y0)))
    fillet = Fillet.of(cfg)
    n = int(round(seconds / furnace.t_s)) + 1
    off = np.zeros(cfg.n_groups)
    lead = np.empty(n)
    for j in range(n):
        t = j * furnace.t_s
        lead[j] = (float(fillet.mean(furnace.true_field())) - float(ref(np.array([t]))[0])) / SETPOINT
        if j + 1 < n:
            furnace.apply(off, t)
    k = int(np.argmax(lead))
    return max(float(lead[k]), 0.0), k * furnace.t_s


def run_one(furnace: str, variant: str, seed: int, learnt: dict[str, Any] | None,
            settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """One run of ``variant`` (with ``settings``, furnace-file keys to values, on top) on ``seed``: its JSON."""
    from twin.config import load_config
    from twin.control.calibration_memory import learnt_parameters
    from twin.furnace.simulated import SimulatedFurnace
    from twin.limits import scenario_limits
    from twin.radiation import radiation_model
    from twin.runs.loop import ClosedLoop
    from twin.scenario import parse_scenario

    cfg = load_config(furnace)
    overrides = {**VARIANTS[variant], **(settings or {})}
    if overrides:
        cfg = cfg.with_overrides(overrides)
    plan_parameters = learnt_parameters(learnt, cfg)
    control: dict[str, Any] = {}
    if plan_parameters is not None:
        control["plan_parameters"] = plan_parameters.model_dump()
    scenario = parse_scenario({"reference": {"setpoint": SETPOINT, "t_E": T_E}, "duration": DURATION,
                               "tc4": [0.5, 0.5], "seed": seed, "truth": "independent", "control": control},
                              scenario_limits(cfg))
    rad = radiation_model(cfg)
    wall = time.perf_counter()
    loop = ClosedLoop(cfg, scenario, rad, furnace=SimulatedFurnace.for_scenario(cfg, scenario, rad))
    snaps = list(loop.run())
    wall = time.perf_counter() - wall
    t = np.array([s.t for s in snaps])
    err = np.abs(np.array([s.true_mean for s in snaps]) - np.array([s.T_ref for s in snaps])) / SETPOINT
    transient = t <= T_E
    metrics = loop.metrics()
    # the run's own lamps-off bound (its header's free response; lamps_off_bound makes it again for stored runs)
    free = np.asarray(loop.record.header.true_mean_lamps_off, float)
    lead, lead_t = float(metrics["true_mean_lead_lamps_off_max"]), float(t[int(np.argmax(
        free - np.array([s.T_ref for s in snaps[: free.size]])))])
    out = {k: metrics.get(k) for k in ("true_mean_error_transient_max", "true_mean_error_steady_max",
                                       "full_power_steady_max", "true_inhomogeneity_steady",
                                       "inhomogeneity_transient_max", "field_estimation_error_steady_max",
                                       "calibration")}
    out.update(
        furnace=furnace, variant=variant, seed=seed, second_run=learnt is not None,
        plan_parameters=None if plan_parameters is None else plan_parameters.model_dump(),
        controller=cfg.control.model_dump(mode="json"),
        true_mean_error_transient_after_15s=float(err[transient & (t >= 15.0)].max()),
        lamps_off_lead_max=lead,
        lamps_off_lead_t=lead_t,
        worst_transient_t=float(t[transient][np.argmax(err[transient])]),
        compute_ms_p50=float(np.percentile(loop.compute_ms, 50)),
        compute_ms_p99=float(np.percentile(loop.compute_ms, 99)),
        wall_s=wall,
    )
    return out


def settings(pairs: list[str] | None) -> dict[str, Any]:
    """``--set KEY=VALUE`` pairs as furnace-file overrides (the value read as JSON, else as a string)."""
    out: dict[str, Any] = {}
    for pair in pairs or ():
        key, sep, text = pair.partition("=")
        if not sep or not key:
            raise SystemExit(f"control_table.py: --set wants KEY=VALUE, got {pair!r}")
        try:
            out[key] = json.loads(text)
        except json.JSONDecodeError:
            out[key] = text
    return out


def cmd_run(args: argparse.Namespace) -> int:
    _patient_plans()
    for seed in args.seeds:
        name = args.name or args.variant
        group = f"{name}-second" if args.second_run else name
        path = Path(args.out) / args.furnace / group / f"seed_{seed}.json"
        if path.exists():
            continue
        learnt = None
        if args.second_run:
            first = Path(args.out) / args.furnace / name / f"seed_{seed}.json"
            while not first.exists():  # the first run of this seed may still be going (another process)
                time.sleep(10.0)
            learnt = json.loads(first.read_text()).get("calibration") or {}
        result = run_one(args.furnace, args.variant, seed, learnt, settings(args.set))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=2))
        sys.stdout.write(json.dumps({k: result[k] for k in ("furnace", "variant", "seed", "second_run",
                                                             "true_mean_error_transient_max",
                                                             "true_mean_error_steady_max", "wall_s")}) + "\n")
        sys.stdout.flush()
    return 0


def cmd_bound(args: argparse.Namespace) -> int:
    """``lamps_off_lead_max`` / ``_t`` into each stored run of ``--out`` without them: the bound depends on the
    furnace, the reference and the seed only, not on the controller."""
    from twin.config import load_config
    from twin.limits import scenario_limits
    from twin.radiation import radiation_model
    from twin.scenario import parse_scenario

    known: dict[tuple[str, int], tuple[float, float]] = {}
    for path in sorted(Path(args.out).glob("*/*/seed_*.json")):
        run = json.loads(path.read_text())
        if "lamps_off_lead_max" in run:
            continue
        key = (run["furnace"], int(run["seed"]))
        if key not in known:
            cfg = load_config(run["furnace"])
            scenario = parse_scenario({"reference": {"setpoint": SETPOINT, "t_E": T_E}, "duration": DURATION,
                                       "tc4": [0.5, 0.5], "seed": key[1], "truth": "independent"},
                                      scenario_limits(cfg))
            known[key] = lamps_off_bound(cfg, scenario, radiation_model(cfg))
        run["lamps_off_lead_max"], run["lamps_off_lead_t"] = known[key]
        path.write_text(json.dumps(run, indent=2))
        sys.stdout.write(f"{path}: lamps-off bound {100 * known[key][0]:.3f} % at t = {known[key][1]:.1f} s\n")
    return 0


def table(out: Path) -> str:
    """The markdown table: one row per furnace and variant (and second run), worst over its seeds."""
    head = "| furnace | controller | seeds | " + " | ".join(h for _, h in COLUMNS) + " |"
    rows = [head, "|" + "---|" * (3 + len(COLUMNS))]
    order = {"default": 0}  # the default furnace first, then the others by name
    for folder in sorted((p for p in out.glob("*/*") if p.is_dir()),
                         key=lambda p: (order.get(p.parent.name, 1), p.parent.name, p.name)):
        runs = [json.loads(f.read_text()) for f in sorted(folder.glob("seed_*.json"))]
        if not runs:
            continue
        furnace, group = folder.parent.name, folder.name
        second = group.endswith("-second")
        variant = group.removesuffix("-second")
        words = {"paper": "paper (LQG, constant c_p, no reserve)"}.get(variant, variant)
        c = runs[0].get("controller") or {}
        if variant != "paper" and c:
            cp = "c_p(T)" if c["plan_heat_capacity"] == "temperature" else "constant c_p"
            words = f"{variant}: {c['feedback'].upper()}, {cp}, limit {c['feedforward_limit']:g}"
            if c.get("mpc_homogeneity") and c["feedback"] == "mpc":
                words += f", variance weight {c['mpc_homogeneity']:g}"
        if second:
            words += ", 2nd run (learnt)"
        cells = [furnace, words, ",".join(str(r["seed"]) for r in runs)]
        for key, _ in COLUMNS:
            bound = BOUNDS.get(furnace, {}).get(key)
            vals = [r.get(key) for r in runs]
            vals = [float(v) for v in vals if isinstance(v, int | float) and np.isfinite(v)]
            if not vals:
                cells.append("n/a")
                continue
            v = max(vals)
            mark = " ✗" if bound is not None and v > bound else ""
            cells.append(f"{100 * v:.2f} %{mark}")
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


BEGIN, END = "<!-- control_table: begin -->", "<!-- control_table: end -->"


def write_into(doc: Path, text: str) -> None:
    """Replace the table between the markers of ``doc`` (docs/control.md)."""
    page = doc.read_text()
    head, rest = page.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    doc.write_text(f"{head}{BEGIN}\n{text}{END}{tail}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--furnace", default="default")
    r.add_argument("--variant", choices=sorted(VARIANTS), default="twin")
    r.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    r.add_argument("--second-run", action="store_true")
    r.add_argument("--out", default="out/control")
    r.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="a furnace-file setting on top of the variant's, e.g. calibration.replan_threshold=0.02")
    r.add_argument("--name", default=None, help="the runs' folder under OUT/FURNACE (default: the variant)")
    b = sub.add_parser("bound", help="add the lamps-off bound to stored runs that lack it (no closed loop: the "
                                    "furnace's free response from the run's seed)")
    b.add_argument("--out", default="out/control")
    t = sub.add_parser("table")
    t.add_argument("--out", default="out/control")
    t.add_argument("--write", nargs="+", default=None, metavar="DOC",
                   help="put the table between the markers of each DOC (docs/control.md, README.md)")
    args = p.parse_args(argv)
    if args.cmd == "run":
        return cmd_run(args)
    if args.cmd == "bound":
        return cmd_bound(args)
    text = table(Path(args.out))
    for doc in args.write or ():
        write_into(Path(doc), text)
    if not args.write:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
