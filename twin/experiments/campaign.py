"""The paper's measurement campaign (section 5): fixed / oscillating specimen x three TC4 positions.

``furnace-twin campaign`` runs the six experiments with the default scenario (t_E = 120 s,
runs of 2 t_E, eta = 3 L_h sin(2 pi t / Pi) with Pi = 0.15 t_E when oscillating), each with several
seeds (``--seeds N``, default 5: the seed drives the TC noise and biases), against the honest truth
by default (``--truth shared`` for the model's own plant), with the twin's default estimator, the paper's
(``--estimator paper``: averaged model, no calibration) or both side by side (``--estimator both``: the
paper's runs go to ``paper_estimator/``).  It writes each run's folder
(``<experiment>/seed_<k>``), ``campaign.md`` putting the paper's reported numbers beside the twin's
worst over the seeds (a bound that fails is marked), the seeds' ranges and the twin's model against
the truth open loop, ``campaign.json`` (the ``--json`` output of product.md), and the Fig. 9
comparison (seed 0).
"""

from __future__ import annotations

import json
import logging
import sys
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.config import FurnaceConfig
from twin.experiments.model_error import MODEL_ERROR_KEYS
from twin.limits import scenario_limits
from twin.runs.metrics import METRIC_KEYS
from twin.scenario import PAPER_ESTIMATOR, ControlSpec, EstimatorSpec, Scenario, parse_scenario

if TYPE_CHECKING:
    from twin.experiments.run import SinkFactory

log = logging.getLogger(__name__)

#: the campaign's estimator choices: the scenario's default (the best measured configuration) and the paper's
ESTIMATORS: dict[str, EstimatorSpec | None] = {"default": None,
                                               "paper": EstimatorSpec(**PAPER_ESTIMATOR.model_dump())}

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


def _mode(e: dict[str, Any]) -> str:
    return "oscillating" if e["oscillation"] else "fixed"


#: the true field's metrics are held to the bound of their estimated counterpart: the paper's bounds are
#: about the specimen, which only a simulation can see
TRUE_BOUND_OF = {"true_mean_error_steady_max": "mean_error_steady_max",
                 "true_mean_error_transient_max": "mean_error_transient_max",
                 "true_inhomogeneity_steady": "inhomogeneity_steady"}


def bound(key: str, mode: str) -> float | None:
    """The paper's value a metric is held to in a specimen mode ("fixed" / "oscillating"), if any."""
    return PAPER[mode].get(key, PAPER[mode].get(TRUE_BOUND_OF.get(key, "")))


def campaign_table(experiments: list[dict[str, Any]]) -> str:
    """Markdown table: each metric, the paper's value and the twin's per experiment (worst over its seeds);
    a value above the paper's for its specimen mode is marked ✗ (the true_* rows against the bound of the
    estimated quantity, shown in parentheses)."""
    head = "| metric | paper fixed | paper osc. | " + " | ".join(e["name"] for e in experiments) + " |"
    sep = "|" + "---|" * (3 + len(experiments))
    rows = [head, sep]
    for key in METRIC_KEYS:
        paper = [_fmt(bound(key, m)) for m in ("fixed", "oscillating")]
        if key in TRUE_BOUND_OF:
            paper = [f"({p})" for p in paper]
        cells = [key, *paper]
        for e in experiments:
            v, b = e["metrics"].get(key), bound(key, _mode(e))
            fails = v is not None and b is not None and np.isfinite(v) and v > b
            cells.append(_fmt(v) + (" ✗" if fails else ""))
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def seed_values(experiment: dict[str, Any], key: str) -> list[float]:
    """The finite values of metric ``key`` over an experiment's seeds (a missing or NaN value left out)."""
    vals = [s["metrics"].get(key) for s in experiment["seeds"]]
    return [float(v) for v in vals if isinstance(v, int | float) and np.isfinite(v)]


def seeds_table(experiments: list[dict[str, Any]]) -> str:
    """Markdown table: each metric's range over the seeds, per experiment (min - max)."""
    head = "| metric | " + " | ".join(e["name"] for e in experiments) + " |"
    rows = [head, "|" + "---|" * (1 + len(experiments))]
    for key in METRIC_KEYS:
        cells = [key]
        for e in experiments:
            vals = seed_values(e, key)
            cells.append(f"{100 * min(vals):.2f} - {100 * max(vals):.2f} %" if vals else "n/a")
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


#: issue 25's bar for the reported band: the share of the fillet's cells x samples of the true field within
#: +-2 sigma, steady window within [lo, hi], transient at least lo_transient
COVERAGE_BAND = (0.90, 0.99)
COVERAGE_TRANSIENT_MIN = 0.85


def coverage_table(experiments: list[dict[str, Any]]) -> str:
    """Markdown table: is the reported band true?  Per experiment the 2-sigma coverage of the true field over the
    fillet (``coverage_2sigma_*``, :func:`twin.runs.metrics.uncertainty_metrics`): the steady window's per seed,
    their mean (the pooled share when the seeds' windows hold the same cells x samples, as a campaign's do: one
    reference and duration, a sigma wherever there is an estimate), how many seeds lie in ``COVERAGE_BAND``, the
    transient's smallest, and the ranges of NEES and NIS (1 when consistent).  Empty when no run has a coverage
    (a campaign without a true field, or stored before the reported covariance)."""
    lo, hi = COVERAGE_BAND
    rows = ["| experiment | steady, per seed (%) | steady, mean over the seeds | seeds in "
            f"{100 * lo:g}-{100 * hi:g} % | transient, smallest | NEES per cell, steady | NIS per reading |",
            "|" + "---|" * 7]
    any_value = False

    def span(vals: list[float]) -> str:
        return f"{min(vals):.2f} - {max(vals):.2f}" if vals else "n/a"

    for e in experiments:
        steady, transient = seed_values(e, "coverage_2sigma_steady"), seed_values(e, "coverage_2sigma_transient")
        if not steady:
            continue
        any_value = True
        mean = float(np.mean(steady))
        inside = sum(lo <= v <= hi for v in steady)
        mark = "" if lo <= mean <= hi else " ✗"
        tmark = "" if transient and min(transient) >= COVERAGE_TRANSIENT_MIN else " ✗"
        rows.append(f"| {e['name']} | " + ", ".join(f"{100 * v:.1f}" for v in steady)
                    + f" | {100 * mean:.1f}{mark} | {inside} of {len(steady)} | "
                    + (f"{100 * min(transient):.1f}{tmark}" if transient else "n/a")
                    + f" | {span(seed_values(e, 'nees_mean'))} | {span(seed_values(e, 'nis_mean'))} |")
    return "\n".join(rows) if any_value else ""


def model_error_table(experiments: list[dict[str, Any]]) -> str:
    """Markdown table of the model's open-loop error against the truth, worst over TC4 positions and seeds."""
    rows = ["| specimen | " + " | ".join(MODEL_ERROR_KEYS) + " |", "|" + "---|" * (1 + len(MODEL_ERROR_KEYS))]
    for mode in ("fixed", "oscillating"):
        runs = [e["model_error"] for e in experiments if _mode(e) == mode]
        if runs:
            rows.append(f"| {mode} | " + " | ".join(_fmt(worst(runs).get(k)) for k in MODEL_ERROR_KEYS) + " |")
    return "\n".join(rows)


def worst(metrics: list[dict[str, Any]]) -> dict[str, Any]:
    """Key by key the worst finite value of several metric objects (None where none is finite): the largest
    error, the smallest coverage (``coverage_*``: the share of the truth inside the reported band)."""
    out: dict[str, Any] = {}
    for key in dict.fromkeys(k for m in metrics for k in m):
        vals = [m.get(key) for m in metrics]
        finite = [float(v) for v in vals if isinstance(v, int | float) and np.isfinite(v)]
        out[key] = (min if key.startswith("coverage_") else max)(finite) if finite else None
    return out


def run_campaign(
    cfg: FurnaceConfig,
    out: Path,
    t_E: float = 120.0,
    radiation: Any = None,
    sink_factories: Iterable[SinkFactory] = (),
    *,
    seeds: int = 5,
    truth: str = "independent",
    truth_radiation: Any = None,
    figures: bool = True,
    estimator: str = "default",
    feedback: str | None = None,
    learnt: dict[tuple[str, int], Any] | None = None,
    only: Iterable[str] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    ship: bool = False,
) -> dict[str, Any]:
    """Run the six experiments, each with the seeds 0 .. seeds - 1; return the product.md ``campaign --json``
    object.  Each experiment's ``metrics`` are the worst over its seeds; ``model_error`` is the twin's model
    against the truth, open loop on each run's inputs (:mod:`twin.experiments.model_error`), also the worst.

    The seed drives the TC noise and (independent truth) the TC biases; runs that start from the same
    readings share their first plan.  ``figures=False`` skips each run's PNGs (the campaign's own stay).
    ``estimator`` is a key of :data:`ESTIMATORS` (``default``: the scenario's own).  ``feedback`` (``lqg`` /
    ``mpc``, None: the furnace's ``[control] feedback``) is every run's ``control.feedback``; ``learnt`` maps
    (experiment, seed) to the plan parameters a run starts from (a second run of the same recipe, issue 26);
    ``only`` keeps the experiments of these names.

    Where the runs go (:mod:`twin.experiments.campaign_runs`): on ``client`` (a ``distributed.Client``; ``ship``
    when its workers may be on other machines), else on the Dask scheduler at ``scheduler`` (files shipped
    back), else on a LocalCluster of ``workers`` processes (default: one per core); ``workers=0`` runs them
    here, one after another, with ``radiation`` and ``truth_radiation`` if given.  The results do not depend
    on where the runs went.  Raises :class:`twin.studies.cluster.ClusterError` when the cluster cannot be
    started or reached.
    """
    from twin.experiments.campaign_runs import CampaignRun, group_by_plan, run_campaign_group
    from twin.experiments.figures import plot_homogeneity_comparison

    if seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds}")
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator must be one of {sorted(ESTIMATORS)}, got {estimator!r}")
    if workers is not None and workers < 0:
        raise ValueError(f"workers must be >= 0 (0: in this process), got {workers}")
    chosen = ESTIMATORS[estimator]
    out.mkdir(parents=True, exist_ok=True)
    wanted = None if only is None else set(only)
    digest = cfg.digest()
    ship = ship or (client is None and scheduler is not None)
    tasks: list[CampaignRun] = []
    bases: dict[str, Scenario] = {}
    for name, base in campaign_scenarios(cfg, t_E):
        if wanted is not None and name not in wanted:
            continue
        bases[name] = base
        for seed in range(seeds):
            update: dict[str, Any] = {"seed": seed, "truth": truth}
            if chosen is not None:
                update["estimator"] = chosen
            plan_parameters = None if learnt is None else learnt.get((name, seed))
            update["control"] = ControlSpec(feedback=feedback, plan_parameters=plan_parameters)  # type: ignore[arg-type]
            scenario = base.model_copy(update=update)
            folder = (out / name / f"seed_{seed}").absolute()  # a worker's working directory may differ
            tasks.append(CampaignRun(name, seed, str(folder), scenario.to_json(), digest,
                                     own_truth=truth == "independent", figures=figures, ship=ship,
                                     keep_series=seed == 0))
    log.info("campaign: %d runs (truth %s, %s estimator)", len(tasks), truth, estimator)
    sinks = list(sink_factories)
    if workers == 0 and client is None and scheduler is None:
        from twin.furnace.simulated.truth import truth_radiation as load_truth_radiation
        from twin.radiation import radiation_model

        rad = radiation if radiation is not None else radiation_model(cfg)
        own = None
        if truth == "independent":
            own = truth_radiation if truth_radiation is not None else load_truth_radiation(cfg)
        plan_cache: dict[Any, Any] = {}
        done = {(r["name"], r["seed"]): r for group in group_by_plan(tasks)  # a group: one loop, its TC4 places
                for r in run_campaign_group(group, sink_factories=sinks, local=(cfg, rad, own), plan_cache=plan_cache)}
        runs = [done[(t.name, t.seed)] for t in tasks]
    else:
        runs = _on_cluster(cfg, tasks, sinks, truth == "independent", client, workers, scheduler)
    experiments: list[dict[str, Any]] = []
    series: dict[str, Any] = {}
    for name, base in bases.items():
        mine = [r for r in runs if r["name"] == name]
        series.update((name, r["series"]) for r in mine if r["series"] is not None)  # seed 0's
        experiments.append({
            "name": name,
            "oscillation": base.oscillation.enabled,
            "tc4": list(base.tc4),
            "metrics": worst([r["metrics"] for r in mine]),
            "model_error": worst([r["model_error"] for r in mine]),
            "seeds": [{"seed": r["seed"], "metrics": r["metrics"], "out": str(out / name / f"seed_{r['seed']}")}
                      for r in mine],
        })
    pairs = [
        (f"TC4 at ({x:g} L_s, {y:g} W_s)", series[f"fixed_tc4_{x:g}"], series[f"oscillating_tc4_{x:g}"])
        for x, y in TC4_POSITIONS if f"fixed_tc4_{x:g}" in series and f"oscillating_tc4_{x:g}" in series
    ]
    if pairs:
        plot_homogeneity_comparison(pairs, out / "homogeneity.png")
    spec = (chosen if chosen is not None else base.estimator).model_dump(mode="json")
    result = {"experiments": experiments, "paper": PAPER, "truth": truth, "seeds": list(range(seeds)),
              "estimator": {"name": estimator, **spec},
              "controller": feedback or cfg.control.feedback, "planned_from_first_run": learnt is not None}
    (out / "campaign.json").write_text(json.dumps(result, indent=2))
    (out / "campaign.md").write_text(campaign_report(result, t_E))
    return result


def _on_cluster(
    cfg: FurnaceConfig, tasks: list[Any], sinks: list[Any], own_truth: bool, client: Any, workers: int | None,
    scheduler: str | None,
) -> list[dict[str, Any]]:
    """The runs on Dask, in the order of ``tasks``; shipped files are written as each run arrives.  Once the
    cluster answers, the tables are made sure of here, so the workers only load them (a worker never
    ray-traces)."""
    from contextlib import nullcontext

    from twin.experiments.campaign_runs import ensure_tables, group_by_plan, run_campaign_runs, write_shipped
    from twin.studies.cluster import study_client

    where = nullcontext((client, 0)) if client is not None else study_client(workers=workers, scheduler=scheduler)
    with where as (cl, n):
        from distributed import as_completed

        ensure_tables(cfg, own_truth)
        if n:
            log.info("campaign: %d runs on %d Dask workers", len(tasks), n)
        furnace = cl.scatter(cfg.model_dump(mode="json"), broadcast=True, hash=False)
        tag = uuid.uuid4().hex[:8]
        futures = {cl.submit(run_campaign_runs, group, furnace, sinks, pure=False,
                             key=f"furnace-twin-campaign-{group[0].name}-seed{group[0].seed}-{tag}"): group
                   for group in group_by_plan(tasks)}
        position = {(t.name, t.seed): i for i, t in enumerate(tasks)}
        runs: list[dict[str, Any] | None] = [None] * len(tasks)
        try:
            for fut in as_completed(list(futures)):
                for run in fut.result():  # a run that failed raises here, as in the serial campaign
                    write_shipped(run)
                    run["files"] = None
                    runs[position[(run["name"], run["seed"])]] = run
                fut.release()
        finally:
            cl.cancel([f for f in futures if not f.done()])
    return [r for r in runs if r is not None]


def campaign_report(result: dict[str, Any], t_E: float) -> str:
    """``campaign.md``: the worst-over-seeds table, the seeds' ranges and the model's own error."""
    ex, n = result["experiments"], len(result["seeds"])
    est = result.get("estimator", {})
    words = (f"; estimator: {est.get('name')} (motion {est.get('motion')}, calibrate {est.get('calibrate')})"
             if est else "")
    text = (
        "# Campaign: the paper's numbers beside the twin's\n\n"
        f"Truth: {result['truth']}{words}; seeds 0..{n - 1}; t_E = {t_E:g} s.  Relative to T_ref(t_E).  Windows: "
        "transient 0..t_E, steady 1.5..2 t_E (product.md).\n\n"
        f"## Worst over the {n} seed{'s' if n != 1 else ''} (✗: above the paper's value for that specimen mode)\n\n"
        + campaign_table(ex)
        + "\n\n## Range over the seeds\n\n"
        + seeds_table(ex)
        + "\n\n## The twin's model against the truth, open loop (each run's inputs, no estimator)\n\n"
        + model_error_table(ex)
        + "\n"
    )
    coverage = coverage_table(ex)
    if coverage:
        lo, hi = COVERAGE_BAND
        text += ("\n## Is the reported band true?\n\nThe share of the fillet's cells x samples where the true "
                 "field lies within +-2 sigma of the estimate (the reported `field_sigma`).  ✗: the mean over the "
                 f"seeds outside {100 * lo:g}-{100 * hi:g} %, or a transient under {100 * COVERAGE_TRANSIENT_MIN:g} "
                 "%.  One run's share carries that run's thermocouple deviations, which three TCs cannot tell from "
                 "the field, so the mean over the seeds is the figure the band is held to (the documentation's "
                 "uncertainty page).\n\n"
                 + coverage + "\n")
    if "paper_estimator" in result:
        text += ("\n## The paper's estimator beside the default (worst over the seeds: paper -> default)\n\n"
                 + comparison_table(result["paper_estimator"]["experiments"], ex) + "\n")
    if "mpc" in result:
        text += ("\n## The MPC beside the LQG (worst over the seeds: LQG -> MPC)\n\n"
                 + comparison_table(ex, result["mpc"]["experiments"]) + "\n")
    for key, words in (("second_run", result.get("controller", "")), ("mpc_second_run", "mpc")):
        if key in result:
            first = ex if key == "second_run" else result["mpc"]["experiments"]
            text += (f"\n## A second run of each recipe ({words}), planned with what the first learnt "
                     "(worst over the seeds: first -> second)\n\n"
                     + comparison_table(first, result[key]["experiments"]) + "\n")
    return text


def learnt_from(result: dict[str, Any], cfg: FurnaceConfig) -> dict[tuple[str, int], Any]:
    """(experiment, seed) -> the plan parameters its run learnt (``[control] plan_learns``; the calibration memory's
    rule, :func:`twin.control.calibration_memory.learnt_parameters`)."""
    from twin.control.calibration_memory import learnt_parameters

    out: dict[tuple[str, int], Any] = {}
    for e in result["experiments"]:
        for s in e["seeds"]:
            out[(e["name"], int(s["seed"]))] = learnt_parameters(s["metrics"].get("calibration"), cfg)
    return out


def comparison_table(before: list[dict[str, Any]], after: list[dict[str, Any]]) -> str:
    """Markdown table of each metric per experiment as ``before -> after`` (each marked ✗ above its bound),
    plus the true field's transient mean error (held to the estimated one's bound) and the TC4 error's
    component at the oscillation frequency for the oscillating experiments."""
    keys = [*METRIC_KEYS, "true_mean_error_transient_max", "true_mean_lead_lamps_off_max",
            "tc4_error_oscillation_amplitude", "full_power_steady_max"]
    rows = ["| metric | " + " | ".join(e["name"] for e in after) + " |", "|" + "---|" * (1 + len(after))]
    for key in keys:
        cells = [key]
        for b, a in zip(before, after, strict=True):
            pair = []
            for e in (b, a):
                v, lim = e["metrics"].get(key), bound(key, _mode(e))
                fails = v is not None and lim is not None and np.isfinite(v) and v > lim
                pair.append(_fmt(v) + (" ✗" if fails else ""))
            cells.append(" -> ".join(pair) if any(e["metrics"].get(key) is not None for e in (b, a)) else "n/a")
        if key == "true_mean_lead_lamps_off_max" and all(c == "n/a" for c in cells[1:]):
            continue  # a campaign stored before the runs had it
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def campaign_command(cfg: FurnaceConfig, args: Any, sink_factories: Iterable[SinkFactory] = ()) -> int:
    from twin.studies.cluster import ClusterError

    if not getattr(args, "verbose", False):  # as `furnace-twin study`: the scheduler's and nannies' INFO lines (and
        # the tracebacks distributed logs at INFO when the LocalCluster closes its connections) stay out
        logging.getLogger("distributed").setLevel(logging.WARNING)
    t_E = float(args.t_e) if args.t_e else 120.0
    if t_E <= 1.0:
        print("furnace-twin campaign: --t-e must be > 1 s", file=sys.stderr)  # noqa: T201
        return 2
    if args.seeds < 1:
        print("furnace-twin campaign: --seeds must be >= 1", file=sys.stderr)  # noqa: T201
        return 2
    out = Path(args.out)
    which = getattr(args, "estimator", "default")
    first = "default" if which == "both" else which
    controller = getattr(args, "controller", "default")
    calibration = getattr(args, "calibration", "none")
    only = getattr(args, "experiments", None)
    feedback = None if controller in ("default", "both") else controller
    if controller == "both":
        feedback = "lqg"
    workers, scheduler = getattr(args, "workers", None), getattr(args, "scheduler", None)
    if workers is not None and workers < 1:
        print(f"furnace-twin campaign: --workers must be >= 1, got {workers}", file=sys.stderr)  # noqa: T201
        return 2
    # each campaign on the cluster: a LocalCluster of --workers processes (default one per core) or --scheduler's
    common: dict[str, Any] = {"sink_factories": sink_factories, "seeds": args.seeds, "truth": args.truth,
                              "only": only, "workers": workers, "scheduler": scheduler}
    try:
        result = run_campaign(cfg, out, t_E, estimator=first, feedback=feedback, **common)
        if which == "both":  # the paper's estimator on the same plants and seeds, beside the default
            result["paper_estimator"] = run_campaign(cfg, out / "paper_estimator", t_E, estimator="paper",
                                                     feedback=feedback, **common)
        if controller == "both":  # the MPC on the same plants and seeds, beside the LQG
            result["mpc"] = run_campaign(cfg, out / "mpc", t_E, estimator=first, feedback="mpc", **common)
        if calibration == "learn":  # each run again, its plan from what the first run of its recipe learnt
            for key, folder in (("second_run", "second_run"), ("mpc_second_run", "mpc/second_run")):
                base = result if key == "second_run" else result.get("mpc")
                if base is None:
                    continue
                result[key] = run_campaign(cfg, out / folder, t_E, estimator=first, feedback=base["controller"],
                                           learnt=learnt_from(base, cfg), **common)
    except ClusterError as exc:  # the scheduler cannot be reached, has no workers, or a cluster cannot start
        print(f"furnace-twin campaign: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    if which == "both" or controller == "both" or calibration == "learn":
        (out / "campaign.json").write_text(json.dumps(result, indent=2))
        (out / "campaign.md").write_text(campaign_report(result, t_E))
    if args.json:
        print(json.dumps(result))  # noqa: T201
    else:
        sys.stdout.write(campaign_report(result, t_E))
        log.info("campaign written to %s", out)
    return 0

